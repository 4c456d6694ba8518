"""``run_fast``: the hand-held pipeline over whole arrays, stage by stage.

The order of :class:`core.pdr.pipeline.Pipeline`'s per-event loop, taken
apart where the data allow it (the stages that do not depend on the attitude
first):

1. the events of the three streams, checked (non-finite, impossible) and
   merged in the pipeline's order, as arrays (vectorised); the sensor-health
   counters (vectorised where no reading sits on a rail or repeats, else
   core's :class:`core.pdr.pipeline.SensorHealth`);
2. the magnetometer calibration over its stream (it never sees the attitude:
   :func:`desktop.fast.attitude.calibrate_magnetometer`; compiled per reading,
   its fits core's Python);
3. the accelerometer norm (eq. 2) and its uniform grid (compiled);
4. the carry-mode detector (issue #17, :mod:`desktop.fast.carry`): its
   features over all hops at once (vectorised), each hop's decision core's;
   its mode and step period at every grid sample;
5. one step detector (eqs. 2-3) per distinct carry-mode gates of
   ``step_gates`` (usually four: the hand-held, the gentle walk's, the swinging hand's
   and the uneven pocket's limb gates), each
   over the whole grid with the carry detector's step period, and the speed
   window at their peaks (compiled);
6. with a GPS fusion (``Pipeline(gnss=...)``) and ``site_from_gps``: the
   sensor event before which the reference gives the attitude filter the
   site's WMM declination and field (``Pipeline.apply_site`` at the GPS event
   where the fusion first has an anchor).  Nothing else of the fusion feeds
   back into the PDR, and neither the anchoring fix nor the moment the fusion
   gets to it depends on the attitude (they depend on the fixes, the receiver
   status and the steps' times and completion), so a copy of the pipeline
   runs the gates and the steps' completion without headings, feeding a copy
   of the fusion, up to that event (:meth:`_FusionEvents.site_event`).  With
   a known ``start`` the anchor is the first fix the fused track accepts: the
   copy then runs with the headings of a first attitude without the site
   (equal to the reference's up to that event), and stages 7 and 8 run again;
7. the attitude filter over all events, the attitude taken at each grid sample
   (compiled after the reference's own start: :mod:`desktop.fast.attitude`),
   in two segments with the site given between them;
8. the rotation smoother over the grid's attitudes (section 4.3, compiled);
9. the gates and the steps (per step, :mod:`desktop.fast.gates`): the active
   mode's peaks are candidates; at a change to a mode with another detector
   that detector's held peaks replace the unconfirmed candidates.  The GPS
   fusion (core's own, per fix and per step) is fed as ``Pipeline.update``
   feeds it: each fix and receiver status before the first grid sample whose
   accelerometer event comes after it (time, then ``recording.stream_order``),
   each step as it completes, the rest at the end (:class:`_Feed`).

The result is :meth:`core.pdr.pipeline.Pipeline.run`'s: the same steps, the
positions and headings within 1e-9 (``tests/test_fast_path.py``), the same
attitude log, counters and labels, and with a GPS fusion the same fused track,
fixes' verdicts, outages and site.  Desktop only: nothing in ``core/`` or
``app/`` imports it, and the phone's per-event path stays the reference.
"""

from __future__ import annotations

import copy
import math
import time

import numpy as np

from core.conventions import ACC, CARRY_MODES, CARRY_POCKET, CARRY_SWINGING, GNSS_STATUS, GPS, GYRO
from core.pdr.pipeline import (IMPOSSIBLE, MAG, SATURATION_FLOOR, AttitudeLog, Pipeline, PipelineResult, SensorHealth,
                               Track)
from core.recording import Recording
from core.pdr.gapbridge import acc_gaps_with_gyro
from core.pdr.steps import GENTLE, GENTLE_SWING, UNEVEN_POCKET
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
    h.skip_quiet(n, int(t_ns[-1]), v[-1])
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
             progress=None, **params) -> PipelineResult:
    """``Pipeline(**params).run(recording)``, computed over whole arrays (see the module docstring).

    Takes the same parameters as :class:`core.pdr.pipeline.Pipeline`, or instead (not both) ``pipeline``: a
    ready-made one to fill, as ``pipeline.run(recording)`` would (it is reset first, as ``run`` resets it: its
    settings stay, e.g. a magnetic declination or site field given to its attitude filter).  A GPS fusion
    (``gnss``) runs as the reference runs it (:class:`_FusionEvents`, :class:`_Feed`).  Attitude filters the
    kernel does not implement (:func:`desktop.fast.attitude.check_supported`) raise ``NotImplementedError``.
    ``timings``, if given, receives the CPU seconds of each stage (the benchmark's breakdown); ``progress``, if
    given, is called with the fraction done (0..1, a rough share of the time) after each stage.
    """
    clock = _Clock(timings, progress)
    if pipeline is not None and params:
        raise TypeError("run_fast takes either a pipeline or the parameters of one, not both")
    recording.stream(ACC, "step detection needs the accelerometer")
    if pipeline is None:
        p = Pipeline(**params)
    else:
        p = pipeline
    keep, p.keep_steps = p.keep_steps, True  # a batch run returns every step, as Pipeline.run does
    try:
        p.reset()
    finally:
        p.keep_steps = keep
    ekf = p.attitude
    fatt.check_supported(ekf)
    _check_no_acc_gap(recording, p)
    _check_gates(p)
    _check_swinging_offset(p)
    ev = _Events(recording, p)
    fusion = _FusionEvents(recording, p, ev) if p.gnss is not None else None
    clock("events", 0.10)
    # 2. the magnetometer calibration over its stream
    calibrator = ekf.mag_calibrator
    mag_pos = ev.pos[fatt.MAG_K]
    v = ev.v.copy()
    cal_ok = np.ones(len(ev.t), dtype=np.bool_)
    if ekf.use_magnetometer and len(mag_pos):
        v[mag_pos], cal_ok[mag_pos] = fatt.calibrate_magnetometer(calibrator, ev.t[mag_pos], ev.v[mag_pos])
    clock("magnetometer calibration (compiled; core's fits where one is due)", 0.15)
    # 3. the grid
    acc_pos = ev.pos[fatt.ACC_K]
    gt, gx, src, restart = grid_of(ev.t[acc_pos], acc_norm(ev.v[acc_pos]), p.grid_rate_hz)
    tick_event = np.ascontiguousarray(acc_pos[src])
    clock("grid", 0.17)
    n_ticks = len(gt)
    # 4. the carry-mode detector (issue #17): its mode and step period at every grid sample
    gyro_pos = ev.pos[fatt.GYRO_K]
    acc_at = ev.v[tick_event]
    track = det_at = None
    if p.carry is not None:
        g = np.searchsorted(gyro_pos, tick_event, side="left") - 1
        has_gyro = g >= 0
        gyro_at = np.where(has_gyro[:, None], ev.v[gyro_pos[np.maximum(g, 0)]] if len(gyro_pos) else 0.0, 0.0)
        track = run_carry(p.carry, gt, acc_at, gyro_at, has_gyro, restart)
        index = {d: i for i, d in enumerate(p.mode_detectors)}
        det_of = p.detector_of
        det_of_mode = np.array([index[det_of[m]] for m in CARRY_MODES], dtype=np.int64)
        det_at = det_of_mode[track.mode]
        if UNEVEN_POCKET in det_of:  # a pocket with very unlike half-strides: the limb gates (Pipeline._gates_key)
            pocket = CARRY_MODES.index(CARRY_POCKET)
            det_at = np.where(track.uneven & (track.mode == pocket), index[det_of[UNEVEN_POCKET]], det_at)
        if GENTLE_SWING in det_of:  # a gentle walk in a swinging hand (Pipeline._gates_key)
            swinging = CARRY_MODES.index(CARRY_SWINGING)
            det_at = np.where(track.gentle & (track.mode == swinging), index[det_of[GENTLE_SWING]], det_at)
        if GENTLE in det_of:  # a gentle walk in a trunk mode: the gentle detector (Pipeline._carry_steps)
            gentle_mode = np.array([p.gentle_applies(m) for m in CARRY_MODES], dtype=bool)
            det_at = np.where(track.gentle & gentle_mode[track.mode], index[det_of[GENTLE]], det_at)
        if n_ticks:
            p.set_carry_state(CARRY_MODES[int(track.mode[-1])], p.mode_detectors[int(det_at[-1])])
    # the smoother's exit of the upright state per grid sample (Pipeline(limb_upright_exit), issue #25)
    exit_at = None
    if p.limb_upright_exit is not None:
        exit_at = np.full(n_ticks, p.base_upright_exit)
        if track is not None:
            limb = np.isin(track.mode, [CARRY_MODES.index(m) for m in p.limb_upright_modes])
            exit_at[limb] = p.limb_upright_exit
    clock("carry-mode detector", 0.35)
    # 5. every step detector (one per distinct gates), the speed window at their peaks
    found = []
    for det in p.mode_detectors:
        det.n_grid = n_ticks
        ev_tick, ev_t, ev_f = detect_steps(det, gt, gx, restart, det.gates,
                                           None if track is None else track.step_period_s, p.flush_at_end,
                                           None if track is None else track.gait_std_m_s2)
        found.append((ev_tick, ev_t, ev_f))
    # a step of the end-of-data flush is found at grid sample n_ticks: the speed window and the rotation are then
    # what they are after the last sample and the last gyroscope event (Pipeline.finish)
    all_ticks = np.unique(np.concatenate([np.minimum(f[0], n_ticks - 1) for f in found]))
    speed = speed_at(p.speed_window, gt, gx, restart, all_ticks)
    clock("steps, speed window", 0.40)
    rot_sum = np.empty(len(gyro_pos))
    rot_n = np.empty(len(gyro_pos), dtype=np.int64)
    rotation_sums(ev.t[gyro_pos], np.ascontiguousarray(ev.v[gyro_pos]), p.rotation_window_ns, rot_sum, rot_n)
    peaks = []
    for ev_tick, ev_t, ev_f in found:
        at = np.minimum(ev_tick, n_ticks - 1)
        g = np.where(ev_tick < n_ticks, np.searchsorted(gyro_pos, tick_event[at], side="left") - 1, len(gyro_pos) - 1)
        gi = np.maximum(g, 0)
        rms = np.where(g >= 0, np.sqrt(np.maximum(rot_sum[gi], 0.0) / np.maximum(rot_n[gi], 1)), 0.0) \
            if len(gyro_pos) else np.zeros(len(ev_tick))
        peaks.append((ev_tick, ev_t, ev_f, rms, speed[np.searchsorted(all_ticks, at)]))
    # 6. the sensor event before which the first anchoring fix gives the attitude filter its site (-1: none)
    site_at, anchor, att = -1, None, None
    if fusion is not None and p.site_from_gps and np.any(fusion.is_gps):
        if getattr(p.gnss, "start", None) is not None:  # the anchor waits on the fused track: the headings first
            att = _attitude_and_smoother(p, ev, v, cal_ok, tick_event, -1, None, exit_at)
            clock("attitude, smoother (without the site)", 0.55)
        site_at, anchor = fusion.site_event(p, gt, tick_event, peaks, track, det_at, att, acc_at)
        clock("GPS site (the fusion's fixes and the steps' schedule)", 0.45)
        if att is not None and site_at >= 0:  # again from the start, the site given where it is due
            p.attitude.reset()
            p.smoother.reset()
            att = None
    # 7, 8. the attitude (in two segments around the site) and the smoother
    if att is None:
        att = _attitude_and_smoother(p, ev, v, cal_ok, tick_event, site_at, anchor, exit_at)
        clock("attitude, smoother", 0.70)
    # 9. gates and steps (the GPS fusion fed as they complete)
    feed = _Feed(p, fusion, tick_event, site_at) if fusion is not None else None
    if len(gt):
        release = att.release(p, StepRelease if feed is None else _FedRelease, gt, acc_at)
        release.feed = feed
        release.run(peaks, track, det_at)
        clock.move("walking direction", release.walkdir_s)
    else:
        if feed is not None:
            feed.to(None)
        p.finish()
    if len(ev.t):
        p.t_ns = int(ev.t[-1])
    if fusion is not None and len(fusion.t):
        p.t_ns = max(p.t_ns, int(fusion.t[-1])) if len(ev.t) else int(fusion.t[-1])
    clock("gates and steps", 1.0)
    return _result(p, recording, AttitudeLog(gt, att.q, att.heading, att.acc_s2, att.mag_s2, att.rejected))


def _check_gates(p: Pipeline) -> None:
    """Refuse the periodic weak-step rescue (``StepGates.rescue_min_periodicity``, issue #25, off by default): the
    fast step kernel does not mirror it."""
    if any(math.isfinite(g.rescue_min_periodicity) for g in p.step_gates.values()):
        raise NotImplementedError("the periodic weak-step rescue (StepGates.rescue_min_periodicity) runs on the "
                                  "reference only")


def _check_swinging_offset(p: Pipeline) -> None:
    """Refuse ``Pipeline(cross_axis_modes)`` and ``Pipeline(turning_keeps_modes)`` (issue #25, off by default): the
    fast walking-direction kernel does not mirror them."""
    if p.cross_axis_modes or p.turning_keeps_modes:
        raise NotImplementedError("Pipeline(cross_axis_modes, turning_keeps_modes) run on the reference only")


def _check_no_acc_gap(recording: Recording, p: Pipeline) -> None:
    """Refuse a recording whose accelerometer stops while the gyroscope runs, when the pipeline bridges such gaps
    (:mod:`core.pdr.gapbridge`, issue #30): the fast path does not mirror the bridge."""
    if p.bridge is None or not recording.has(GYRO):
        return
    n = acc_gaps_with_gyro(recording.streams[ACC].t_ns, recording.streams[GYRO].t_ns, p.bridge.min_gap_s)
    if n:
        raise NotImplementedError(f"the accelerometer has {n} gap(s) of {p.bridge.min_gap_s:g} s or more while the "
                                  "gyroscope ran, and the fast path does not bridge them (core.pdr.gapbridge)")


class _Attitude:
    """The attitude on the grid (``q``, the log's columns, ``j_init``: the first sample with the filter started)
    and the smoother's forward vector and heading there, ``upright`` per sample from ``j_init`` on."""

    def __init__(self, q, acc_s2, mag_s2, rejected, j_init, east, north, heading, upright):
        self.q, self.acc_s2, self.mag_s2, self.rejected, self.j_init = q, acc_s2, mag_s2, rejected, j_init
        self.east, self.north, self.heading, self.upright = east, north, heading, upright

    def release(self, p: Pipeline, cls, gt, acc_at) -> StepRelease:
        """A :class:`desktop.fast.gates.StepRelease` (or subclass ``cls``) for ``p`` on the grid ``gt`` with these
        forward vectors, its walking-direction stage fed where the pipeline has one (``acc_at``: the accelerometer
        reading behind each grid sample)."""
        j = self.j_init
        release = cls(p, gt, gt[j:], self.east[j:], self.north[j:], self.rejected)
        if getattr(p, "walkdir", None) is not None:
            axes = [(0.0, 0.0, -1.0) if u else (0.0, 1.0, 0.0) for u in self.upright.tolist()] \
                if p.smoother.auto_axis else [p.smoother.forward_b] * len(self.upright)
            release.walking_direction(j, self.q, acc_at, axes)
        return release


def _attitude_and_smoother(p: Pipeline, ev: _Events, v, cal_ok, tick_event, site_at: int, anchor,
                           exit_at=None) -> _Attitude:
    """The attitude filter over all events, taken at each grid sample (``tick_event[j]``: the event behind sample
    ``j``), the site given before event ``site_at`` (``Pipeline.apply_site(anchor)``; -1: none); then the
    rotation smoother over the grid's attitudes (section 4.3), its final state into ``p.smoother``."""
    ekf = p.attitude
    n_ticks = len(tick_event)
    out_q = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (n_ticks, 1))
    out_acc_s2, out_mag_s2 = np.full(n_ticks, np.nan), np.full(n_ticks, np.nan)
    out_rej = np.zeros(n_ticks, dtype=np.bool_)
    applied = []

    def give_site():
        """The reference's ``Pipeline.apply_site`` at the anchoring fix (once)."""
        applied.append(True)
        p.apply_site(anchor)

    calibrator = ekf.mag_calibrator
    ekf.mag_calibrator = None
    try:
        i0, j0, j_init = fatt.start_with_reference(ekf, ev.kind, ev.t, v, cal_ok, tick_event, out_q, out_acc_s2,
                                                   out_mag_s2, out_mag_rej=out_rej, hook_at=site_at, hook=give_site)
        if i0 < len(ev.t):
            st = fatt.KernelState(ekf, len(ev.pos[fatt.GYRO_K]), len(ev.pos[fatt.ACC_K]), len(ev.pos[fatt.MAG_K]))
            j = j0
            if site_at >= 0 and not applied:  # two segments, the site given between them
                j = st.run(ev.kind[:site_at], ev.t[:site_at], v[:site_at], cal_ok[:site_at], i0, tick_event, j,
                           out_q, out_acc_s2, out_mag_s2, out_rej)
                give_site()
                st.new_settings(ekf, refresh_references=bool(p.site.get("declination_deg") is not None))
                i0 = site_at
            st.run(ev.kind, ev.t, v, cal_ok, i0, tick_event, j, out_q, out_acc_s2, out_mag_s2, out_rej)
            st.write_back(ekf)
        if site_at >= 0 and not applied:  # after the last sensor event
            give_site()
    finally:
        ekf.mag_calibrator = calibrator
    east, north, heading = (np.full(n_ticks, np.nan) for _ in range(3))
    e, nn, h, upright, counters = smooth_headings(p.smoother, out_q[j_init:],
                                                  None if exit_at is None else exit_at[j_init:])
    if exit_at is not None and j_init < n_ticks:
        p.smoother.upright_exit = float(exit_at[-1])  # as the reference leaves it after its last smoothed sample
    east[j_init:], north[j_init:], heading[j_init:] = e, nn, h
    p.smoother.upright = bool(counters[0])
    p.smoother.n_axis_switches, p.smoother.n_upright = int(counters[1]), int(counters[2])
    if p.smoother.upright:
        p.smoother.forward_b = (0.0, 0.0, -1.0)
    return _Attitude(out_q, out_acc_s2, out_mag_s2, out_rej, j_init, east, north, heading, upright)


class _SiteDue(Exception):
    """Raised by a scouting :class:`_Feed` at the GPS event where the reference gives the attitude its site."""

    def __init__(self, at: int, anchor: tuple):
        super().__init__(at)
        self.at, self.anchor = at, anchor


class _FusionEvents:
    """The GPS fusion's events (``gps`` fixes and ``gnss_status``), merged as ``Pipeline.run`` merges them.

    ``ins[m]``: how many valid sensor events come before fusion event ``m`` in the pipeline's order (time,
    then ``recording.stream_order``, then row), i.e. the sensor event it is handed over before.  Also does
    what ``Pipeline.run`` does for a fusion: the streams counted as seen, the fusion's time zero, the Unix
    offset from the recording's metadata.
    """

    def __init__(self, recording: Recording, p: Pipeline, ev: _Events):
        names = ([GPS] + ([GNSS_STATUS] if recording.has(GNSS_STATUS) else [])) if recording.has(GPS) else []
        sensors = [n for n in (GYRO, ACC, p.mag_stream) if recording.has(n)]
        order = recording.stream_order(sensors + names)
        rank = {n: i for i, n in enumerate(order)}
        ts, rs, rows, vals = [], [], [], []
        for name in names:
            s = recording.streams[name]
            t = np.asarray(s.t_ns, dtype=np.int64)
            p.seen[name] = len(t)
            ts.append(t)
            rs.append(np.full(len(t), rank[name], dtype=np.int64))
            rows.append(np.arange(len(t), dtype=np.int64))
            vals.append(s.values)
        empty = np.zeros(0, dtype=np.int64)
        t, r, row = (np.concatenate(x) if x else empty for x in (ts, rs, rows))
        idx = np.lexsort((row, r, t))
        self.t, self.rank, self.row = t[idx], r[idx], row[idx]
        self.is_gps = self.rank == rank.get(GPS, -1)
        self._vals = {rank[n]: v for n, v in zip(names, vals)}
        big = len(order)
        code_rank = np.array([rank.get(n, big) for n in (GYRO, ACC, p.mag_stream)], dtype=np.int64)
        ev_rank = code_rank[ev.kind.astype(np.int64)] if len(ev.t) else np.zeros(0, np.int64)
        lo = np.searchsorted(ev.t, self.t, side="left")
        hi = np.searchsorted(ev.t, self.t, side="right")
        self.ins = np.array([a + int(np.count_nonzero(ev_rank[a:b] < rk)) if b > a else a
                             for a, b, rk in zip(lo.tolist(), hi.tolist(), self.rank.tolist())], dtype=np.int64)
        if names:  # as Pipeline.run: only with fixes to fuse
            p.gnss.set_time_zero(recording.t0_ns)
            off = recording.metadata.get("unix_offset_ns")
            if p.unix_offset_ns is None and isinstance(off, int):
                p.unix_offset_ns = off

    def values(self, m: int) -> tuple:
        """Fusion event ``m``'s values, as the pipeline's event loop hands them over."""
        return tuple(self._vals[int(self.rank[m])][int(self.row[m])].tolist())

    def site_event(self, p: Pipeline, gt, tick_event, peaks, track, det_at, att=None, acc_at=None) -> tuple:
        """``(sensor event, anchor)`` before which the reference gives the attitude filter its site, or
        ``(-1, None)``.

        The fix that anchors the walk and the moment the fusion gets to it (a fix waits for the first step after
        it) depend on the fixes, the receiver status and the steps' times and completion, none of which depends on
        the attitude.  So a copy of the pipeline runs the gates and the steps' completion without any heading,
        feeding a copy of the fusion, up to the GPS event where the reference would call ``apply_site``.  With a
        known ``start`` the anchor is the first fix the fused track accepts: then the copy runs with the headings
        of the attitude without the site (``att``, an :class:`_Attitude`; the same as the reference's up to there).
        """
        scout = copy.deepcopy(p)
        if att is None:
            scout.walkdir = None
        feed = _Feed(scout, self, tick_event, -1, scout=True)
        try:
            if len(gt):
                if att is None:
                    none = np.zeros(0)
                    release = _FedRelease(scout, gt, gt[:0], none, none, np.zeros(len(gt), dtype=np.bool_))
                else:
                    release = att.release(scout, _FedRelease, gt, acc_at)
                release.feed = feed
                release.run(peaks, track, det_at)
            else:
                feed.to(None)
        except _SiteDue as due:
            return due.at, due.anchor
        return -1, None


class _FedRelease(StepRelease):
    """:class:`desktop.fast.gates.StepRelease` feeding the pipeline's GPS fusion (``feed``, a :class:`_Feed`).

    Only the order of the fusion's calls matters to it: before a grid sample's steps complete (``release``) the
    fixes and status before its accelerometer event; each completed step at once (``complete``); at the end the
    rest of the fixes, the last steps, then the fusion's ``finish`` (``Pipeline.finish``).
    """

    feed = None

    def release(self, k: int) -> None:
        self.feed.tick(k)
        super().release(k)

    def complete(self, ev, heading: float, regressors: tuple, mag_rejected: bool):
        step = super().complete(ev, heading, regressors, mag_rejected)
        self.feed.step(step)
        return step

    def finish(self) -> None:
        self.feed.to(None)
        super().finish()
        self.feed.finish()


class _Feed:
    """The pipeline's GPS fusion fed as ``Pipeline.update`` feeds it: each fix and status at its event, each step
    as it completes (:class:`desktop.fast.gates.StepRelease` calls :meth:`tick` before a grid sample's work,
    :meth:`step` per completed step, :meth:`to` with None and :meth:`finish` at the end).

    ``site_at``: the sensor event before which the attitude got its site (-1: none); a scouting feed instead
    raises :class:`_SiteDue` where the reference would give it.
    """

    def __init__(self, p: Pipeline, events: _FusionEvents, tick_event, site_at: int, scout: bool = False):
        self.p, self.ev, self.tick_event, self.site_at, self.scout = p, events, tick_event, site_at, scout
        self.m = 0
        self.anchored = False

    def to(self, i: int | None) -> None:
        """The fusion events before sensor event ``i`` (None: all)."""
        ev, p = self.ev, self.p
        g = p.gnss
        n = len(ev.t)
        while self.m < n and (i is None or ev.ins[self.m] <= i):
            m = self.m
            self.m += 1
            if not ev.is_gps[m]:
                g.add_status(int(ev.t[m]), ev.values(m))
                continue
            g.add_fix(int(ev.t[m]), ev.values(m))
            if not self.anchored and p.site_from_gps and g.anchor is not None:
                self.anchored = True  # where Pipeline.update calls apply_site
                if self.scout:
                    raise _SiteDue(int(ev.ins[m]), g.anchor)
                if int(ev.ins[m]) != self.site_at:
                    raise RuntimeError(f"the fast path gave the site before sensor event {self.site_at}, the "
                                       f"reference gives it before {int(ev.ins[m])}")
        if i is None and not self.scout and self.site_at >= 0 and not self.anchored:
            raise RuntimeError("the fast path gave the attitude a site the reference does not give")

    def tick(self, k: int) -> None:
        """Before grid sample ``k``'s work: the fusion events before its accelerometer event."""
        self.to(int(self.tick_event[k]))

    def step(self, step) -> None:
        """A completed step, to the fusion (``Pipeline._complete``)."""
        self.p.fused.append(self.p.gnss.add_step(step))

    def finish(self) -> None:
        self.p.gnss.finish()


class _Clock:
    """CPU seconds since the last call, added to ``timings[name]`` (nothing without a dict); the fraction of the run
    done at the end of that stage to ``progress`` (nothing without one)."""

    def __init__(self, timings: dict | None, progress=None):
        self.timings = timings
        self.progress = progress
        self.done = 0.0
        self.t = time.process_time()

    def __call__(self, name: str, done: float | None = None) -> None:
        if self.progress is not None and done is not None and done > self.done:
            self.done = done
            self.progress(done)
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
    counters.update(peaks_replayed_mode_change=p.n_replayed, peaks_replaced_mode_change=p.n_replaced_mode,
                    walk_start_steps=p.n_walk_start_steps)
    if p.flush_at_end:
        counters["steps_flushed_at_end"] = p.n_flushed
    counters["nonfinite_skipped"] = dict(p.n_nonfinite)
    counters.update(p.health_counters())
    counters.update(p.gap_counters())  # empty: a recording with a gap to bridge is refused
    counters["attitude"] = a.counters()
    if p.carry is not None:
        counters["carry"] = p.carry.counters()
    fusion = p.gnss.result() if p.gnss is not None else None
    if fusion is not None:
        fusion.counters["site"] = p.site
    return PipelineResult(list(p.steps), Track.from_steps(p.steps), att, p.labels(), recording, counters, fusion)
