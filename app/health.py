"""Sensor health: actual rate, jitter and dropped events per stream (plain Python, no Kivy).

Everything is computed from the events' own timestamps, so the same numbers
come out live on the phone and when a recording is replayed:

rate
    events per second over the last ``window_s`` seconds of sensor time.
jitter
    standard deviation of the event intervals in that window (ms), gaps left out:
    :func:`core.recording.jitter_s`, the same as ``pdr info``.
gaps / missed
    an interval longer than ``gap_factor`` times the nominal interval (the
    running median interval) is a gap; ``round(dt / nominal) - 1`` events are
    counted as *missed* (never delivered by the OS).
out of order
    events whose timestamp is not later than the previous one of the same
    stream (the session drops them).
queue drops
    events the source discarded because the UI did not drain its queue in
    time (reported by the source, added by :meth:`HealthMonitor.snapshot`).
pauses
    the session tells the monitor when its source was stopped on purpose
    (:meth:`HealthMonitor.pause`: the user paused, or the sensors were off
    while the app was away); the first interval after it is counted as
    paused time, not as a gap, so a minute in the background is not shown
    as thousands of dropped events.  A gap while the source runs (the phone
    stopped delivering, e.g. asleep without a wake lock) still counts.
"""

from __future__ import annotations

import math
import statistics
from collections import deque
from dataclasses import dataclass

from core.recording import jitter_s


@dataclass
class StreamStats:
    """One row of the health panel."""

    stream: str
    events: int
    rate_hz: float
    median_dt_ms: float
    jitter_ms: float
    gaps: int
    missed: int
    out_of_order: int
    queue_drops: int = 0
    accuracy: str = ""

    @property
    def dropped(self) -> int:
        """Events lost: missed by the OS (timestamp gaps) plus discarded by the queue."""
        return self.missed + self.queue_drops


class StreamHealth:
    """Running statistics of one stream's timestamps."""

    def __init__(self, name: str, *, window_s: float = 5.0, max_window: int = 1000, gap_factor: float = 1.8,
                 min_events_for_gaps: int = 10):
        self.name = name
        self.window_ns = int(window_s * 1e9)
        self.gap_factor = float(gap_factor)
        self.min_events_for_gaps = int(min_events_for_gaps)
        self._t: deque = deque(maxlen=max_window)
        self._dt: deque = deque(maxlen=max_window)
        self.events = 0
        self.gaps = 0
        self.missed = 0
        self.out_of_order = 0
        self._nominal_ns: float | None = None
        self._since_nominal = 0
        self.last_t_ns: int | None = None
        self.paused_ns = 0  #: sensor time between a pause and the first event after it
        self._pause_at: int | None = None

    def pause(self, at_ns: int | None = None) -> None:
        """The source was stopped on purpose after sensor time ``at_ns`` (default: this stream's last event):
        the interval across it is a pause, not a gap (events still waiting in the reorder buffer may come first)."""
        self._pause_at = int(at_ns) if at_ns is not None else self.last_t_ns

    def accept(self, t_ns: int) -> bool:
        """Account for one event; returns False (and counts it) if it is out of order."""
        t_ns = int(t_ns)
        last = self.last_t_ns
        if last is not None and t_ns <= last:
            self.out_of_order += 1
            return False
        self.events += 1
        pause_at = self._pause_at
        if pause_at is not None and (last is None or last > pause_at):
            self._pause_at = pause_at = None  # nothing of this stream before the pause: nothing to bridge
        if pause_at is not None and t_ns > pause_at:
            self.paused_ns += t_ns - last
            self._pause_at = None
        elif last is not None:
            dt = t_ns - last
            nominal = self._nominal()
            if nominal and dt > self.gap_factor * nominal:
                self.gaps += 1
                self.missed += max(int(round(dt / nominal)) - 1, 0)
            self._dt.append(dt)
        self._t.append(t_ns)
        self.last_t_ns = t_ns
        while len(self._t) > 2 and self._t[0] < t_ns - self.window_ns:
            self._t.popleft()
        return True

    def _nominal(self) -> float | None:
        """Running median interval (re-estimated every 50 events)."""
        if len(self._dt) < self.min_events_for_gaps:
            return None
        self._since_nominal += 1
        if self._nominal_ns is None or self._since_nominal >= 50:
            self._nominal_ns = float(statistics.median(self._dt))
            self._since_nominal = 0
        return self._nominal_ns

    def stats(self) -> StreamStats:
        t = self._t
        n = len(t)
        rate = (n - 1) / ((t[-1] - t[0]) * 1e-9) if n > 1 and t[-1] > t[0] else 0.0
        # intervals inside the rate window
        k = max(n - 1, 0)
        recent = list(self._dt)[-k:] if k else []
        if len(recent) >= 2:
            med = statistics.median(recent) * 1e-6
            jit = jitter_s(recent) * 1e-6  # ns -> ms; the one definition (gaps left out), as in pdr info
        else:
            med = jit = math.nan
        return StreamStats(self.name, self.events, rate, med, jit, self.gaps, self.missed, self.out_of_order)


class HealthMonitor:
    """Health of every stream of a session, plus the magnetometer trust flag from the pipeline."""

    def __init__(self, **stream_kwargs):
        self._kw = stream_kwargs
        self.streams: dict[str, StreamHealth] = {}
        self.mag_trusted: bool | None = None
        self.pauses = 0  #: times the source was stopped on purpose

    def pause(self, at_ns: int | None = None) -> None:
        """The source was stopped on purpose after sensor time ``at_ns`` (see the module docstring): no stream
        counts the pause as a gap."""
        self.pauses += 1
        for h in self.streams.values():
            h.pause(at_ns)

    def accept(self, stream: str, t_ns: int) -> bool:
        h = self.streams.get(stream)
        if h is None:
            h = self.streams[stream] = StreamHealth(stream, **self._kw)
        return h.accept(t_ns)

    def snapshot(self, queue_drops: dict | None = None, accuracy: dict | None = None) -> list[StreamStats]:
        from app.sources import ACCURACY_NAMES  # noqa: PLC0415 - avoid a cycle at import time

        rows = []
        for name in sorted(self.streams):
            s = self.streams[name].stats()
            s.queue_drops = int((queue_drops or {}).get(name, 0))
            if accuracy and name in accuracy:
                s.accuracy = ACCURACY_NAMES.get(accuracy[name], str(accuracy[name]))
            rows.append(s)
        return rows

    def format(self, queue_drops: dict | None = None, accuracy: dict | None = None, mag_line: bool = True) -> str:
        """The health panel as monospace text (``mag_line``: end with whether the magnetometer is trusted)."""
        rows = self.snapshot(queue_drops, accuracy)
        w = max([7] + [len(s.stream) + 1 for s in rows])  # other devices' streams: "acc@left_foot"
        lines = [f"{'sensor':<{w}}{'rate Hz':>9}{'jitter ms':>11}{'dropped':>9}{'gaps':>6}{'order':>7}  accuracy"]
        for s in rows:
            jit = f"{s.jitter_ms:.2f}" if math.isfinite(s.jitter_ms) else "-"
            lines.append(f"{s.stream:<{w}}{s.rate_hz:>9.1f}{jit:>11}{s.dropped:>9d}{s.gaps:>6d}"
                         f"{s.out_of_order:>7d}  {s.accuracy or '-'}")
        if self.pauses:
            paused = max((h.paused_ns for h in self.streams.values()), default=0) * 1e-9
            lines.append(f"paused {self.pauses}x, {paused:.0f} s (not counted as dropped)")
        if not mag_line:
            return "\n".join(lines)
        if self.mag_trusted is None:
            trust = "unknown"
        else:
            trust = "yes" if self.mag_trusted else "NO (rejected by the adaptive filter)"
        lines.append(f"magnetometer trusted: {trust}")
        return "\n".join(lines)
