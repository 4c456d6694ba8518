"""The rotation gate, the bout gate and the steps' completion over whole arrays (per step, cheap).

Second implementation of what :class:`core.pdr.pipeline.Pipeline` does per
peak and per grid sample (``_candidate``, ``_release``, ``_step_heading``,
``finish``): the rotation RMS comes from a compiled running sum over the
gyroscope events, and the release runs only at the grid samples where
something can change (a peak arrives, a step's heading falls due, a bout's
time runs out) instead of at every one.  A step's heading is
:func:`core.pdr.heading.interval_heading` over the forward vectors the
pipeline would still hold, through the pipeline's own walking-direction stage
(:class:`core.pdr.walkdir.WalkingDirection`, fed every grid sample in Python:
it is not ported); the stride model (eq. 4) and the dead reckoner (eq. 1) are
core's own classes.
"""

from __future__ import annotations

import math
import time

import numpy as np

from core.pdr.heading import interval_heading
from core.pdr.pipeline import DEFAULT_STEP_DURATION_S, Step
from core.pdr.steps import StepEvent
from desktop.fast.jit import kernel


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
        self.cands: list[list] = []  # [event, heading or None, confirmed, regressors]
        self.bout_len = 0
        self.delay_ns = int(pipe.heading_delay_s * 1e9)
        self.gap_ns = int(pipe.detector.max_step_interval_s * 1e9)
        self.keep_ns = self.gap_ns + self.delay_ns + 1_000_000_000
        self._walkdir = None  # (first grid sample, q, acc, axes) when the pipeline has a walking-direction stage
        self._wd_next = 0
        #: CPU seconds spent in the walking-direction stage (the benchmark's breakdown)
        self.walkdir_s = 0.0

    def walking_direction(self, j_init: int, q, acc, axes) -> None:
        """Feed the pipeline's walking-direction stage as it is fed: every grid sample after the attitude's start,
        with the attitude ``q`` (n, 4), the accelerometer reading ``acc`` (n, 3) behind each sample and the
        smoother's axis there (``axes``, from ``j_init`` on)."""
        self._walkdir = (j_init, q, acc, axes)
        self._wd_next = j_init

    def _walkdir_to(self, k: int, step_ticks: set) -> None:
        """The walking-direction stage updated with the grid samples up to ``k``."""
        if self._walkdir is None:
            return
        t0 = time.process_time()
        j_init, q, acc, axes = self._walkdir
        wd = self.p.walkdir
        e, n = self.fwd_e, self.fwd_n
        for j in range(self._wd_next, k + 1):
            a = acc[j]
            wd.update(int(self.grid_t[j]), tuple(q[j].tolist()), float(a[0]), float(a[1]), float(a[2]),
                      float(e[j - j_init]), float(n[j - j_init]), j in step_ticks, axes[j - j_init])
        self._wd_next = max(self._wd_next, k + 1)
        self.walkdir_s += time.process_time() - t0

    def run(self, ev_tick, events: list[StepEvent], rms, regressors) -> None:
        """All the candidates (found at grid samples ``ev_tick``, rotation RMS ``rms`` there), then the end."""
        gt = self.grid_t
        t = np.array([e.t_ns for e in events], dtype=np.int64)
        due = np.maximum(np.searchsorted(gt, t + self.delay_ns, side="left"), ev_tick)
        gap = np.searchsorted(gt, t + self.gap_ns, side="right")
        ticks = np.unique(np.concatenate([ev_tick, due, gap]))
        ticks = ticks[ticks < len(gt)]
        steps_at = set(ev_tick.tolist())
        m = 0
        for k in ticks.tolist():
            self._walkdir_to(k, steps_at)
            while m < len(ev_tick) and ev_tick[m] == k:
                self.candidate(events[m], float(rms[m]), tuple(float(x) for x in regressors[m]))
                m += 1
            self.release(k)
        self._walkdir_to(len(gt) - 1, steps_at)
        self.finish()

    def candidate(self, ev: StepEvent, rms: float, regressors: tuple) -> None:
        p = self.p
        if ev.duration_s != ev.duration_s:  # first step after a pause: a new bout
            self.drop_unconfirmed()
        if rms > p.max_rotation_rms_rad_s:
            p.n_rejected_rotation += 1
            self.drop_unconfirmed()
            return
        self.cands.append([ev, None, False, regressors])
        self.bout_len += 1
        if self.bout_len >= p.min_bout_steps:
            for c in self.cands:
                c[2] = True

    def drop_unconfirmed(self) -> None:
        kept = [c for c in self.cands if c[2]]
        self.p.n_rejected_bout += len(self.cands) - len(kept)
        self.cands = kept
        self.bout_len = 0

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
        return heading if wd is None else wd.step_heading(heading, self.p.walking_direction, None)

    def release(self, k: int) -> None:
        cands = self.cands
        if not cands:
            return
        tg = int(self.grid_t[k])
        for c in cands:
            if c[1] is None and c[0].t_ns + self.delay_ns <= tg:
                c[1] = self.heading(c[0], k)
        if not cands[-1][2] and tg - cands[-1][0].t_ns > self.gap_ns:
            self.drop_unconfirmed()
        while cands and cands[0][2] and cands[0][1] is not None:
            ev, h, _, reg = cands.pop(0)
            self.complete(ev, h, reg, bool(self.mag_rejected[k]))

    def finish(self) -> None:
        self.drop_unconfirmed()
        last = len(self.grid_t) - 1
        rejected = self.p.attitude.mag_rejected  # the filter's state after the last event
        for ev, h, _, reg in self.cands:
            self.complete(ev, self.heading(ev, last) if h is None else h, reg, rejected)
        self.cands = []

    def complete(self, ev: StepEvent, heading: float, regressors: tuple, mag_rejected: bool) -> None:
        p = self.p
        feats = p.step_features(ev, regressors)
        length = p.stride_model.length_m(feats)  # eq. 4
        if heading != heading:  # no attitude yet
            heading = p.attitude.initial_yaw_rad
        east, north = p.reckoner.update(length, heading)  # eq. 1
        p.steps.append(Step(p.n_steps, ev.t_ns, length, heading, east, north, feats,
                            not mag_rejected and p.attitude.use_magnetometer))
        p.n_steps += 1
