"""The rotation gate, the bout gate and the steps' completion over whole arrays (per step, cheap).

Second implementation of what :class:`core.pdr.pipeline.Pipeline` does per
peak and per grid sample (``_candidate``, ``_release``, ``_step_heading``,
``finish``): the rotation RMS comes from a compiled running sum over the
gyroscope events, and the release runs only at the grid samples where
something can change (a peak arrives, a step's heading falls due, a bout's
time runs out) instead of at every one.  A step's heading is
:func:`core.pdr.heading.interval_heading` over the forward vectors the
pipeline would still hold, through the pipeline's own walking-direction stage
(:class:`core.pdr.walkdir.WalkingDirection`, run over the whole grid at once by
:func:`desktop.fast.walkdir.walking_direction_over_grid` and read at each step
through core's own ``step_heading``); the stride model (eq. 4) and the dead reckoner (eq. 1) are
core's own classes.  With carry-mode detection (issue #17) the candidates
are the peaks of the detector of the mode in force; at a change to a mode with
another detector its held peaks (the last ``rotation_hold_s``) replace the
unconfirmed candidates, as ``Pipeline._switch_detector`` does, and every step
is labelled with its carry mode (``Pipeline.step_carry_mode`` on the detector's
state at the step's completion).
"""

from __future__ import annotations

import math
import time

import numpy as np

from core.conventions import CARRY_MODES, CARRY_SWINGING
from core.pdr.heading import interval_heading
from core.pdr.pipeline import DEFAULT_STEP_DURATION_S, Step, StepCandidate, heading_key
from core.pdr.steps import StepEvent
from desktop.fast.jit import kernel
from desktop.fast.walkdir import walking_direction_over_grid


@kernel
def rotation_sums(t_ns, w, window_ns, out_sum, out_n):
    """The pipeline's running sum of |w|^2 over the trailing window, and its count, after each gyro event."""
    lo = 0
    s = 0.0
    for i in range(len(t_ns)):
        w2 = w[i, 0] * w[i, 0] + w[i, 1] * w[i, 1] + w[i, 2] * w[i, 2]
        s += w2
        limit = t_ns[i] - window_ns
        while t_ns[lo] < limit:
            x = w[lo, 0] * w[lo, 0] + w[lo, 1] * w[lo, 1] + w[lo, 2] * w[lo, 2]
            s -= x
            lo += 1
        out_sum[i] = s
        out_n[i] = i + 1 - lo


class StepRelease:
    """Candidates through the rotation and bout gates to completed steps (the pipeline's per-step logic).

    ``pipe`` is the reference :class:`core.pdr.pipeline.Pipeline` whose settings, stride model, dead
    reckoner, step list and counters it uses and fills.  ``grid_t``: the grid; ``fwd_t``, ``fwd_e``,
    ``fwd_n``: the smoothed forward vector on the grid samples after the attitude started;
    ``mag_rejected``: the filter's flag at each grid sample.
    """

    def __init__(self, pipe, grid_t, fwd_t, fwd_e, fwd_n, mag_rejected):
        self.p = pipe
        self.grid_t = grid_t
        self.fwd_t, self.fwd_e, self.fwd_n = fwd_t, fwd_e, fwd_n
        self.mag_rejected = mag_rejected
        self.cands: list[StepCandidate] = []
        self.bout_len = 0
        self.delay_ns = int(pipe.heading_delay_s * 1e9)
        self.gap_ns = int(pipe.detector.max_step_interval_s * 1e9)
        self.keep_ns = self.gap_ns + self.delay_ns + 1_000_000_000
        if getattr(pipe, "carry", None) is not None:  # peaks replayed at a mode change are up to rotation_hold_s old
            self.keep_ns += int(pipe.rotation_hold_s * 1e9)
        self.hold_ns = int(pipe.rotation_hold_s * 1e9)
        self.min_gap_ns = int(pipe.detector.min_step_interval_s * 1e9)
        self.confirmed_ns = -(1 << 62)  # the last confirmed candidate's peak time
        self.completed_ns = -(1 << 62)  # the last completed step's peak time
        #: ``Pipeline(hold_while_settling=...)`` with carry detection: steps wait while the walk's mode settles
        self.settle_hold = bool(getattr(pipe, "hold_while_settling", False)) and getattr(pipe, "carry", None) is not None
        #: ``Pipeline(recount_at_settle=True)``: where the settling ends on the same detector, its held peaks recount
        self.recount = self.settle_hold and bool(getattr(pipe, "recount_at_settle", False))
        #: ``Pipeline(walk_start_step=True)``: the index of the gentle detector that looks back (None: off)
        start_det = getattr(pipe, "walk_start_detector", None)
        self.start_d = next(i for i, d in enumerate(pipe.mode_detectors) if d is start_det) \
            if start_det is not None else None
        self.active_d = 0  # the detector whose peaks are candidates at the grid sample being processed
        self.carry = None  # the carry detector's per-sample track (desktop.fast.carry.CarryTrack), when it runs
        self.peaks: list = []
        self.k = None  # the grid sample being processed (None: the end)
        self._walkdir = None  # (first grid sample, q, acc, axes) when the pipeline has a walking-direction stage
        self._wd_trace = None  # the stage over the whole grid (desktop.fast.walkdir), made at the first _walkdir_to
        #: CPU seconds spent in the walking-direction stage (the benchmark's breakdown)
        self.walkdir_s = 0.0

    def walking_direction(self, j_init: int, q, acc, axes) -> None:
        """Feed the pipeline's walking-direction stage as it is fed: every grid sample after the attitude's start,
        with the attitude ``q`` (n, 4), the accelerometer reading ``acc`` (n, 3) behind each sample and the
        smoother's axis there (``axes``, from ``j_init`` on)."""
        self._walkdir = (j_init, q, acc, axes)
        self._wd_trace = None

    def _walkdir_to(self, k: int, step_ticks: set) -> None:
        """The walking-direction stage as the grid samples up to ``k`` leave it: the whole grid in one pass
        (:func:`desktop.fast.walkdir.walking_direction_over_grid`, at the first call: ``step_ticks`` is complete
        by then), then the estimate after sample ``k`` put into the pipeline's stage (at the last sample its
        whole final state)."""
        if self._walkdir is None:
            return
        t0 = time.process_time()
        if self._wd_trace is None:
            j_init, q, acc, axes = self._walkdir
            self._wd_trace = walking_direction_over_grid(self.p.walkdir, self.grid_t, q, acc, self.fwd_e,
                                                         self.fwd_n, step_ticks, axes, j_init)
        self._wd_trace.at(self.p.walkdir, k)
        self.walkdir_s += time.process_time() - t0

    def run(self, peaks: list, carry=None, det_at=None) -> None:
        """All the candidates, then the end.

        ``peaks``: per step detector of the pipeline (``pipe.mode_detectors``' order; one without carry
        detection) ``(ev_tick, ev_t, ev_f, rms, regressors)``: the grid samples at which its peaks are found, the
        :class:`StepEvent` fields of each (its time; the rest, in order), the rotation RMS and the speed regressors
        there.  With carry detection,
        ``carry`` is the detector's per-sample :class:`desktop.fast.carry.CarryTrack` and ``det_at[k]`` the
        index of the mode's detector at grid sample ``k``; the active detector's peaks are candidates, and at a
        change of detector the new one's held peaks replace the unconfirmed candidates.
        """
        gt = self.grid_t
        n_grid = len(gt)
        self.carry = carry
        self.peaks = [(np.asarray(tk, dtype=np.int64), np.asarray(t, dtype=np.int64), f, r, g)
                      for tk, t, f, r, g in peaks]
        if det_at is None:
            det_at = np.zeros(n_grid, dtype=np.int64)
        prev = np.concatenate([[0], det_at[:-1]])
        switch = det_at != prev
        det_switch = switch  # a change of detector: no live peak at that sample (a recount keeps it)
        ticks = [np.flatnonzero(switch)]
        if self.settle_hold and carry is not None:
            # the settling before each sample's decision; the release can change where it ends
            self.settled_before = np.concatenate([[carry.settling_before], carry.settling[:-1]])
            ticks.append(np.flatnonzero(self.settled_before & ~carry.settling))
            # a change of mode at the sample, and the walk's start only held open before it (settle_walk_s)
            self.changed = np.diff(carry.n_changes, prepend=0) != 0
            self.walk_before = np.concatenate([[carry.settling_walk_before], carry.settling_walk[:-1]])
            if self.recount:  # a change of mode while settling, on the same detector: recount (Pipeline._carry_steps)
                switch = switch | (self.settled_before & self.changed)
                ticks.append(np.flatnonzero(switch))
        steps_at = set()
        for d, (tk, t, _, _, _) in enumerate(self.peaks):
            # a peak's own sample, the one where its heading falls due, the one where its bout's time runs out:
            # the release can change only there (a replayed peak's at the change of detector, in the list too)
            ticks += [tk, np.searchsorted(gt, t + self.delay_ns, side="left"),
                      np.searchsorted(gt, t + self.gap_ns, side="right")]
            if self.settle_hold:  # where a step held by the settling is held no longer
                ticks.append(np.searchsorted(gt, t + self.hold_ns, side="left"))
            tk = tk[tk < n_grid]  # (the end-of-data flush's steps are no live peaks)
            live = tk[(det_at[tk] == d) & ~det_switch[tk]]
            steps_at.update(live.tolist())
        ticks = np.unique(np.concatenate(ticks))
        ticks = ticks[ticks < n_grid]
        nxt = [0] * len(self.peaks)
        for k in ticks.tolist():
            self._walkdir_to(k, steps_at)
            self.k = k
            d = int(det_at[k])
            self.active_d = d
            if switch[k]:
                self.switch(d, k)
            else:
                tk = self.peaks[d][0]
                m = nxt[d]
                while m < len(tk) and tk[m] < k:
                    m += 1
                while m < len(tk) and tk[m] == k:
                    self._peak(d, m)
                    m += 1
                nxt[d] = m
            self.release(k)
        self._walkdir_to(n_grid - 1, steps_at)
        self.k = None
        self.finish()

    def _rotation_limit(self) -> float:
        """The pipeline's rotation gate in force at the current grid sample (wider for a periodic swinging arm)."""
        p = self.p
        c = self.carry
        k = -1 if self.k is None else self.k
        if c is None or not bool(c.rotation_periodic[k]):
            return p.max_rotation_rms_rad_s
        mode = CARRY_MODES[int(c.mode[k])]
        if mode not in p.wide_rotation_modes:
            return p.max_rotation_rms_rad_s
        pending = int(c.pending[k])
        wide = (mode == CARRY_SWINGING or pending < 0 or p.step_gates.get(CARRY_MODES[pending]) == p.step_gates.get(mode)
                or (p.wide_while_pending_limb and CARRY_MODES[pending] in p.wide_rotation_modes))
        return max(p.max_rotation_rms_rad_s, p.swinging_max_rotation_rms_rad_s) if wide else p.max_rotation_rms_rad_s

    def switch(self, d: int, k: int) -> None:
        """The mode at grid sample ``k`` has detector ``d``: its held peaks (found by ``k``, within
        ``rotation_hold_s``, after the last confirmed step) replace the unconfirmed candidates
        (``Pipeline._switch_detector``)."""
        p = self.p
        settled = (self.settle_hold and self.carry is not None and bool(self.settled_before[k])
                   and (bool(self.changed[k]) or not bool(self.walk_before[k])))
        headings = {heading_key(c.event): c.heading_rad for c in self.cands
                    if c.heading_rad is not None} if settled and self.recount else None
        kept = [] if settled else [c for c in self.cands if c.confirmed]
        p.n_replaced_mode += len(self.cands) - len(kept)
        self.cands = kept
        self.bout_len = 0
        if settled:
            self.confirmed_ns = self.completed_ns
        tk, t = self.peaks[d][:2]
        hi = int(np.searchsorted(tk, k, side="right"))
        lo = int(np.searchsorted(t[:hi], max(self.confirmed_ns + self.min_gap_ns + 1,
                                             int(self.grid_t[k]) - self.hold_ns), side="left"))
        n_rot = p.n_rejected_rotation  # counted once, when the peak was live
        for m in range(lo, hi):
            p.n_replayed += 1
            self._peak(d, m)
        p.n_rejected_rotation = n_rot
        if headings:  # a recount keeps the replaced candidates' headings (Pipeline._switch_detector)
            for c in self.cands:
                if c.heading_rad is None:
                    c.heading_rad = headings.get(heading_key(c.event))

    def _peak(self, d: int, m: int) -> None:
        """Peak ``m`` of detector ``d`` made a candidate (its StepEvent built only now: most are never needed)."""
        _, t, f, rms, regs = self.peaks[d]
        self.candidate(StepEvent(int(t[m]), *f[m].tolist()), float(rms[m]), tuple(regs[m].tolist()))

    def candidate(self, ev: StepEvent, rms: float, regressors: tuple) -> None:
        p = self.p
        if ev.duration_s != ev.duration_s:  # first step after a pause: a new bout
            self.drop_unconfirmed()
        if rms > self._rotation_limit():
            p.n_rejected_rotation += 1
            self.drop_unconfirmed()
            return
        self.cands.append(StepCandidate(ev, None, False, regressors))
        self.bout_len += 1
        if self.bout_len >= p.min_bout_steps:
            before_ns = self.confirmed_ns
            for c in self.cands:
                c.confirmed = True
            self.confirmed_ns = ev.t_ns
            if self.start_d is not None and self.bout_len == p.min_bout_steps:
                self._walk_start_step(before_ns)

    def _walk_start_step(self, before_ns: int) -> None:
        """``Pipeline._walk_start_step``: the gentle detector's peak (found by the current grid sample) one step period
        before a new bout's first step is inserted before the bout as the walk's first step."""
        p = self.p
        k = len(self.cands) - self.bout_len
        if self.start_d == self.active_d or k < 0 or self.bout_len < 2:
            return
        first, second = self.cands[k].event, self.cands[k + 1].event
        if first.duration_s == first.duration_s:
            return
        period = second.t_ns - first.t_ns
        f = p.walk_start_cadence_frac
        lo, hi = first.t_ns - (1.0 + f) * period, first.t_ns - (1.0 - f) * period
        after = max(before_ns, self.completed_ns) + self.min_gap_ns
        tk, t, feats, rms, regs = self.peaks[self.start_d]
        for m in range(int(np.searchsorted(tk, self.k, side="right")) - 1, -1, -1):
            tm = int(t[m])
            if tm < lo or tm <= after:
                return
            if tm <= hi and float(rms[m]) <= self._rotation_limit():
                self.cands.insert(k, StepCandidate(StepEvent(tm, *feats[m].tolist()), None, True,
                                                   tuple(regs[m].tolist())))
                p.count_walk_start_step(tm)  # a recount inserts the same one again: counted once
                return

    def drop_unconfirmed(self) -> None:
        kept = [c for c in self.cands if c.confirmed]
        self.p.n_rejected_bout += len(self.cands) - len(kept)
        self.cands = kept
        self.bout_len = 0

    def _mode_now(self) -> str | None:
        """The carry mode in force at the current grid sample (None without carry detection)."""
        c = self.carry
        if c is None:
            return None
        return CARRY_MODES[int(c.mode[-1 if self.k is None else self.k])]

    def heading(self, ev: StepEvent, k: int) -> float:
        """The step's heading with the forward vectors the pipeline holds at grid sample ``k``."""
        tg = int(self.grid_t[k])
        hi = int(np.searchsorted(self.fwd_t, tg, side="right"))
        if hi == 0:
            return math.nan
        lo = int(np.searchsorted(self.fwd_t, self.fwd_t[hi - 1] - self.keep_ns, side="left"))
        duration = ev.duration_s if ev.duration_s == ev.duration_s else DEFAULT_STEP_DURATION_S
        t1 = ev.t_ns + self.delay_ns
        t0 = t1 - int(duration * 1e9)
        heading = interval_heading(self.fwd_t[lo:hi], self.fwd_e[lo:hi], self.fwd_n[lo:hi], t0, t1)
        wd = getattr(self.p, "walkdir", None)
        return heading if wd is None else wd.step_heading(heading, self.p.walking_direction, self._mode_now())

    def release(self, k: int) -> None:
        cands = self.cands
        if not cands:
            return
        tg = int(self.grid_t[k])
        for c in cands:
            if c.heading_rad is None and c.event.t_ns + self.delay_ns <= tg:
                c.heading_rad = self.heading(c.event, k)
        if not cands[-1].confirmed and tg - cands[-1].event.t_ns > self.gap_ns:
            self.drop_unconfirmed()
            cands = self.cands  # the list it kept (Pipeline._release)
        hold = self.hold_ns if self.settle_hold and self.carry is not None and bool(self.carry.settling[k]) \
            else -(1 << 62)
        while cands and cands[0].confirmed and cands[0].heading_rad is not None and tg - cands[0].event.t_ns >= hold:
            c = cands.pop(0)
            self.complete(c.event, c.heading_rad, c.regressors, bool(self.mag_rejected[k]))

    def finish(self) -> None:
        p = self.p
        if getattr(p, "flush_at_end", False) and len(self.grid_t):  # Pipeline._flush_detector: the active detector's
            n_grid = len(self.grid_t)                                 # steps found at the end (grid sample n_grid)
            # the detector in force after the last sample (the fast pipeline set the pipeline's from det_at[-1])
            self.active_d = next(i for i, d in enumerate(p.mode_detectors) if d is p.active_detector) \
                if getattr(p, "carry", None) is not None else 0
            tk = self.peaks[self.active_d][0]
            self.k = n_grid - 1  # the state after the last sample (the rotation gate, a walk-start look-back)
            ms = range(int(np.searchsorted(tk, n_grid, side="left")), len(tk))
            for m in ms:
                self._peak(self.active_d, m)
            p.n_flushed = len(ms)
            self.k = None
        self.drop_unconfirmed()
        last = len(self.grid_t) - 1
        rejected = self.p.attitude.mag_rejected  # the filter's state after the last event
        for c in self.cands:
            self.complete(c.event, self.heading(c.event, last) if c.heading_rad is None else c.heading_rad,
                          c.regressors, rejected)
        self.cands = []

    def _carry_mode_of(self, t_ns: int) -> str:
        """The carry mode a step completed now is labelled with: the pipeline's rule
        (``Pipeline.step_carry_mode``) on the detector's state at the current grid sample."""
        c = self.carry
        if c is None or self.k is None:  # no detector, or the end: the detector's final state
            return self.p.step_carry_mode(t_ns)
        return self.p.step_carry_mode(t_ns, c.changes[:int(c.n_changes[self.k])], CARRY_MODES[int(c.mode[self.k])])

    def complete(self, ev: StepEvent, heading: float, regressors: tuple, mag_rejected: bool) -> Step:
        """The step completed with the pipeline's own :meth:`core.pdr.pipeline.Pipeline.add_step` (eqs. 4, 1)."""
        self.completed_ns = ev.t_ns
        return self.p.add_step(ev, heading, regressors, mag_rejected, self._carry_mode_of(ev.t_ns))
