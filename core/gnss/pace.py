"""The receiver's own speed against the walker's steps: a stream that does not see the walker walk (issue #26).

Indoors a phone keeps reporting fixes with a plausible 4-6 m accuracy, but the
receiver does not track the walker: on the IPIN museum loops (tuning routes 01,
02, 22) the speed it reports, integrated over 30 s of walking, is 0.3-0.55 of
the distance the steps walked (median per file), and its fixes are off by
2-23 m in one direction for minutes (time-correlated errors that no per-fix
gate sees).  Outdoors, on the tuning walk (``thomasdingemanse_lopen``), the
same ratio is 0.75-1.03 (5th to 95th percentile of its windows); the iOS
walks' Doppler speed reads 15-25 % low, not half.

This is Kubrak et al.'s (2006) second bad-GPS test carried over to the
receiver: their filter learns the walker's speed model from GPS, and "if a
strong variability in the regression coefficients is detected (which
obviously does not reflect a real change in the pace of the pedestrian), then
the GPS measurements are assumed unreliable".  A walker's stride does not
halve; a receiver whose speed says it did is not following the walker.

:class:`ReceiverPaceCheck` streams the screened fixes (their reported speed)
with the dead-reckoned position at their time.  Over the last ``window_s`` in
which the steps walked at least ``min_walk_m`` and at least ``min_fixes`` fixes
reported a speed, the receiver's distance (speed times the time to the
previous fix) against the steps' (the dead-reckoned path between the fixes'
times) below ``min_ratio`` marks the stream **slow**; it stays slow until
``memory_s`` has passed without such a window (minute by minute: the fixes
between slow windows carry the same stale solution).  The judge
(:class:`core.gnss.judge.GpsJudge`) then calls the stream unusable and the
fused track is the dead-reckoned one.  A fix without a speed (nan) is no
evidence; a recording whose fixes carry no speed is never judged slow (waiting for the evidence at a walk's start is the
judge's ``evidence_first``, :class:`core.gnss.judge.JudgeSettings`).  Nor
is a speed of exactly 0: phones report it without a velocity solution (two
outdoor report walks start with 4-7 s of 0.0 while the walker walks off, the
receiver still converging), and counted it would keep a good outdoor stream
out for a minute; indoors the nonzero speeds alone still read under half the
steps' (IPIN tuning: the rule then gives the same median, 2.53 m).

The thresholds were set on the tuning split only (IPIN routes 01, 02, 21, 22;
the outdoor walk ``thomasdingemanse_lopen``): ``min_ratio`` 0.5 lies between
the indoor medians (0.32-0.55, zeros counted; 0.41-0.82 without them, with
windows under 0.5 in every file of routes 01, 02 and 22) and the outdoor 5th
percentile (0.75; that walk reports no zero).  The exclusion of zeros was
chosen after seeing the outdoor report walks' cold starts (see above): not
from the tuning split, which has no such start.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

#: the longest time (s) between two fixes compared (the speed of one fix says nothing of a gap's walk)
MAX_FIX_DT_S = 2.0


@dataclass(frozen=True)
class PaceSettings:
    """When the receiver's speed says it does not see the walker walk (units in the names)."""

    window_s: float = 30.0
    #: the steps must have walked this far in the window (m) for it to count (a walker standing says nothing)
    min_walk_m: float = 10.0
    min_fixes: int = 8
    #: the receiver's distance over the steps' below this: slow
    min_ratio: float = 0.5
    #: the stream stays slow this long (s) after its last slow window
    memory_s: float = 60.0


@dataclass(frozen=True)
class PaceState:
    """The check's view at one fix (diagnostics as data)."""

    ratio: float = math.nan  #: the receiver's distance over the steps' in the window (nan: no evidence)
    walked_m: float = math.nan  #: the steps' path in the window (m)
    slow_now: bool = False


class ReceiverPaceCheck:
    """Whether the receiver's reported speed follows the walker's steps (see the module docstring)."""

    def __init__(self, settings: PaceSettings | None = None):
        self.settings = settings or PaceSettings()
        self.reset()

    def reset(self) -> None:
        self._win: deque = deque()  # (t_ns, receiver distance m or nan, steps' distance m)
        self._prev: tuple | None = None  # (t_ns, pdr_e, pdr_n) of the last fix
        self.last_slow_ns: int | None = None
        self.last = PaceState()
        self.n_fixes = 0
        self.n_slow = 0
        self.min_ratio_seen = math.inf

    def add_fix(self, t_ns: int, speed_m_s: float, pdr_en) -> PaceState:
        """A screened fix's time and reported speed (nan: none), and the dead-reckoned position (m) at its time."""
        s = self.settings
        t_ns = int(t_ns)
        pe, pn = float(pdr_en[0]), float(pdr_en[1])
        recv = steps = math.nan
        dt = (t_ns - self._prev[0]) * 1e-9 if self._prev is not None else math.nan
        if 0.0 < dt <= MAX_FIX_DT_S:  # after a gap (an outage, screened-out fixes) the pair says nothing
            recv = speed_m_s * dt if (math.isfinite(speed_m_s) and speed_m_s > 0.0) else math.nan
            steps = math.hypot(pe - self._prev[1], pn - self._prev[2])
        if math.isfinite(pe) and math.isfinite(pn):
            self._prev = (t_ns, pe, pn)
        w = self._win
        if math.isfinite(steps):
            w.append((t_ns, recv, steps))
        while w and w[0][0] <= t_ns - int(s.window_s * 1e9):
            w.popleft()
        pairs = [(r, d) for _, r, d in w if math.isfinite(r)]
        walked = sum(d for _, d in pairs)
        ratio = math.nan
        if len(pairs) >= s.min_fixes and walked >= s.min_walk_m:
            ratio = sum(r for r, _ in pairs) / walked
            self.min_ratio_seen = min(self.min_ratio_seen, ratio)
            if ratio < s.min_ratio:
                self.last_slow_ns = t_ns
        slow = self.last_slow_ns is not None and t_ns - self.last_slow_ns <= int(s.memory_s * 1e9)
        self.n_fixes += 1
        self.n_slow += slow
        self.last = PaceState(ratio, walked, slow)
        return self.last

    def summary(self) -> dict:
        return {"fixes": self.n_fixes, "fixes_slow": self.n_slow,
                "min_ratio": self.min_ratio_seen if math.isfinite(self.min_ratio_seen) else None,
                "slow_now": self.last.slow_now}
