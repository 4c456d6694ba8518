"""Floors from the barometer: relative altitude, floor changes, stairs or lift.

Pressure comes in the recording's ``pressure`` stream (hPa, as Android, Sensor Logger, phyphox and
GetSensorData report it).  :class:`FloorEstimator` turns it into

* a **relative altitude** (m above the first reading) by the standard-atmosphere barometric formula
  (ICAO / US Standard Atmosphere 1976, troposphere)::

      h = T0 / L * (1 - (p / p_ref) ** (R L / (g M)))      T0 / L = 44330.8 m,  R L / (g M) = 0.190263

  low-passed (first order, ``smoothing_s``);
* a **floor number** (0 at the start), changed only by a *sustained* altitude step: the smoothed
  altitude leaves the current floor's level by more than ``start_fraction`` of a storey, then settles
  (vertical speed below ``settle_rate_m_s`` for ``settle_s``); the number of floors is the altitude
  change divided by ``storey_height_m``, rounded;
* **how**: the vertical speed of the change (over its middle 80 %: the time between 10 % and 90 % of
  the altitude change, on a lightly smoothed altitude, ``speed_smoothing_s``) says *stairs* (a few
  tenths of a metre per second: about 0.17 m of rise per step at 1-2 steps per second), *lift* (above
  ``lift_rate_m_s``: lifts travel at 1 m/s and more), or *slope* (below ``min_stairs_rate_m_s``: a ramp
  or a hill, which is not a floor change; the level follows it).  Outdoors there are no floors: a
  change during which a GNSS fix at least as good as ``outdoor_hacc_m`` was seen
  (:meth:`FloorEstimator.note_fix`) is a slope too.  A change of less than a floor on stairs is a
  landing: its height is added to the next flight (within ``landing_max_s``), so two half-storey
  flights with a pause between them make a floor.

Drift: the weather moves sea-level pressure by up to a few hPa per hour (about 8 m of apparent
altitude per hPa).  The current floor's level is not the altitude at arrival but follows the smoothed
altitude with a time constant of ``level_tau_s`` while the altitude is steady (not on a flight of
stairs), so a drift of 3 hPa/h (0.007 m/s) lags by its rate times ``level_tau_s`` (0.2 m at 30 s),
well inside the start band of a floor change.

Streaming :meth:`FloorEstimator.update` (the app) and batch :meth:`FloorEstimator.run` (files) share the
kernel.  A reading that is not finite or outside ``valid_hpa`` is skipped and counted, never let into
the state.  Diagnostics are data: :attr:`FloorEstimator.counters`, every :class:`FloorChange`, and per
sample the altitude, the level and the floor (batch).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

#: readings kept for the speed of a change (at 25 Hz, 10 minutes)
_MAX_TRACE = 15000
_TRACE_NS = 600 * 1_000_000_000
#: a good fix this long before a change started still says outdoors; the speed's trace starts this early
_FIX_MARGIN_NS = 10 * 1_000_000_000
#: ICAO standard atmosphere: T0 / L (m) and the exponent R L / (g M) of the barometric formula
_H_SCALE_M = 44330.8
_EXPONENT = 0.190263


def altitude_m(p_hpa, p_ref_hpa):
    """Altitude (m) of pressure ``p_hpa`` above the level where the pressure is ``p_ref_hpa``
    (standard-atmosphere barometric formula; about 8.3 m per hPa near sea level)."""
    return _H_SCALE_M * (1.0 - np.power(np.asarray(p_hpa, dtype=float) / p_ref_hpa, _EXPONENT))


@dataclass(frozen=True)
class FloorSettings:
    """Settings of :class:`FloorEstimator` (units in the names)."""

    #: height of one storey (m): floor changes are altitude changes in multiples of it
    storey_height_m: float = 3.5
    #: time constant of the altitude's low-pass (s)
    smoothing_s: float = 2.0
    #: time constant of the lighter low-pass whose altitude gives a change's speed (s)
    speed_smoothing_s: float = 0.5
    #: floors are counted when the altitude is this much (storeys) past half a storey from the floor's
    #: altitude: a landing half a storey up is no floor, 0.5 + margin storeys is one
    round_margin: float = 0.15
    #: a landing (a change of less than a floor) is added to the next flight if it comes within this (s)
    landing_max_s: float = 60.0
    #: a floor change starts when the smoothed altitude is this fraction of a storey away from the level
    start_fraction: float = 0.35
    #: altitudes within this of the level count as "on the level" (m): the change started when it was last so
    on_level_band_m: float = 0.5
    #: ... and ends when the vertical speed (over ``rate_window_s``) stays below this (m/s) ...
    settle_rate_m_s: float = 0.08
    #: ... for this long (s)
    settle_s: float = 4.0
    rate_window_s: float = 2.0
    #: the level follows the altitude on a floor with this time constant (s): weather drift, not steps
    level_tau_s: float = 30.0
    #: mean vertical speed above which a change is a lift (m/s); below ``min_stairs_rate_m_s`` a slope
    lift_rate_m_s: float = 0.5
    min_stairs_rate_m_s: float = 0.07
    #: a GNSS fix this good (horizontal accuracy, m) during a change means outdoors: a slope, not a floor
    outdoor_hacc_m: float = 10.0
    #: readings outside this range are not pressures at human altitudes (hPa)
    valid_hpa: tuple = (300.0, 1100.0)


@dataclass(frozen=True)
class FloorChange:
    """One sustained altitude step: a floor change (``floors`` != 0) or a slope/half-storey shift (0)."""

    t_start_ns: int  #: last time the altitude was on the old level
    t_end_ns: int  #: when it settled on the new one
    floors: int  #: floors gone up (negative: down); 0 for a slope or a landing less than half a storey away
    delta_m: float  #: altitude change (m)
    rate_m_s: float  #: mean vertical speed between leaving the old level and reaching the new one (m/s)
    kind: str  #: "stairs", "lift" or "slope"
    floor_after: int

    @property
    def t_mid_ns(self) -> int:
        return (self.t_start_ns + self.t_end_ns) // 2


@dataclass
class FloorResult:
    """A batch run: per reading, and the changes."""

    t_ns: np.ndarray
    altitude_m: np.ndarray  #: smoothed altitude above the first reading (m); nan for skipped readings
    level_m: np.ndarray  #: the current floor's level (m)
    floor: np.ndarray  #: (int) floor number after the reading (0 at the start)
    changes: list
    counters: dict = field(default_factory=dict)

    def floor_at(self, t_ns) -> np.ndarray:
        """The floor at times ``t_ns`` (e.g. the steps'): a change counts from its midpoint (on the stairs
        half-way), before the first reading the start floor 0."""
        return floors_at(self.changes, t_ns)

    def summary(self) -> dict:
        floors = [0] + [c.floor_after for c in self.changes]
        ok = np.isfinite(self.altitude_m)
        return {
            "floor_changes": sum(1 for c in self.changes if c.floors),
            "floors_visited": sorted(set(floors)),
            "final_floor": floors[-1],
            "stairs": sum(1 for c in self.changes if c.floors and c.kind == "stairs"),
            "lifts": sum(1 for c in self.changes if c.floors and c.kind == "lift"),
            "slopes": sum(1 for c in self.changes if c.kind == "slope"),
            "altitude_range_m": float(np.ptp(self.altitude_m[ok])) if np.any(ok) else math.nan,
            **self.counters,
        }


def floors_at(changes, t_ns) -> np.ndarray:
    """Floor number at times ``t_ns`` from a list of :class:`FloorChange` (each counts from its midpoint)."""
    t = np.asarray(t_ns, dtype=np.int64)
    real = [c for c in changes if c.floors]
    if not real:
        return np.zeros(t.shape, dtype=int)
    mids = np.array([c.t_mid_ns for c in real], dtype=np.int64)
    after = np.array([0] + [c.floor_after for c in real], dtype=int)
    return after[np.searchsorted(mids, t, side="right")]


class FloorEstimator:
    """Relative altitude and floor from pressure; see the module docstring.

    ``update(t_ns, p_hpa)`` -> the :class:`FloorChange` completed by this reading (or None);
    ``run(stream)`` -> :class:`FloorResult` (``stream``: a recording's ``pressure`` stream, or any object
    with ``t_ns`` and ``values`` (n, 1) in hPa).
    """

    def __init__(self, settings: FloorSettings | None = None, **overrides):
        s = settings or FloorSettings()
        if overrides:
            from dataclasses import replace  # noqa: PLC0415

            s = replace(s, **overrides)
        if not (s.storey_height_m > 0 and s.smoothing_s > 0 and s.level_tau_s > 0 and s.settle_s >= 0):
            raise ValueError("storey height, smoothing and level time constants must be positive")
        self.settings = s
        self.reset()

    def reset(self) -> None:
        self.p_ref_hpa = math.nan  #: the first valid reading: altitude 0
        self.altitude_m = math.nan  #: smoothed altitude (m)
        self.level_m = math.nan  #: where the walker is now: the level the altitude is compared with (m)
        self.carry_m = 0.0  #: altitude of the landing reached since the last floor (m): the next flight adds to it
        self._carry_t: int | None = None
        self.floor = 0
        self.moving = False  #: a change is under way
        self.changes: list[FloorChange] = []
        self.counters = {"readings": 0, "skipped": 0, "aborted_changes": 0}
        self._t_prev: int | None = None
        self._hist: deque = deque()  # (t_ns, altitude) over the rate window
        self._t_on_level: int | None = None
        self._start_level = math.nan
        self._t_start: int | None = None
        self._settled_since: int | None = None
        self._fast = math.nan  # the lightly smoothed altitude (m)
        self._trace: deque = deque(maxlen=_MAX_TRACE)  # (t_ns, fast altitude) of the last minutes
        self._good_fix_t: int | None = None  # last GNSS fix better than outdoor_hacc_m

    # -- the kernel ----------------------------------------------------------------------------------
    def update(self, t_ns: int, p_hpa: float) -> FloorChange | None:
        s = self.settings
        t = int(t_ns)
        p = float(p_hpa)
        if not (math.isfinite(p) and s.valid_hpa[0] <= p <= s.valid_hpa[1]) or (
                self._t_prev is not None and t <= self._t_prev):
            self.counters["skipped"] += 1
            return None
        self.counters["readings"] += 1
        if not math.isfinite(self.p_ref_hpa):
            self.p_ref_hpa = p
        h = float(altitude_m(p, self.p_ref_hpa))
        if self._t_prev is None:
            self.altitude_m = self.level_m = self._fast = h
            self._t_prev = self._t_on_level = t
            self._hist.append((t, h))
            self._trace.append((t, h))
            return None
        dt = (t - self._t_prev) * 1e-9
        self._t_prev = t
        a = self.altitude_m + (h - self.altitude_m) * (1.0 - math.exp(-dt / s.smoothing_s))
        self.altitude_m = a
        self._fast += (h - self._fast) * (1.0 - math.exp(-dt / s.speed_smoothing_s))
        trace = self._trace
        trace.append((t, self._fast))
        while trace[0][0] < t - _TRACE_NS:
            trace.popleft()
        hist = self._hist
        hist.append((t, a))
        window_ns = int(s.rate_window_s * 1e9)
        while len(hist) > 2 and hist[1][0] <= t - window_ns:
            hist.popleft()
        t0, a0 = hist[0]
        rate = (a - a0) / ((t - t0) * 1e-9) if t > t0 else 0.0
        if not self.moving:
            return self._on_level(t, a, dt, rate)
        return self._in_change(t, a, rate)

    def _on_level(self, t: int, a: float, dt: float, rate: float) -> None:
        s = self.settings
        off = a - self.level_m
        if abs(off) <= s.on_level_band_m:
            self._t_on_level = t
        if abs(off) > s.start_fraction * s.storey_height_m:
            self.moving = True
            self._start_level = self.level_m
            self._t_start = self._t_on_level
            self._settled_since = None
            return None
        # the level follows slowly while the altitude is steady: weather drift, not a flight of stairs
        if abs(rate) <= s.settle_rate_m_s:
            self.level_m += off * (1.0 - math.exp(-dt / s.level_tau_s))
        if self.carry_m and (t - self._carry_t) * 1e-9 > s.landing_max_s:
            self.carry_m = 0.0  # stayed: a mezzanine, not a landing
        return None

    def _in_change(self, t: int, a: float, rate: float) -> FloorChange | None:
        s = self.settings
        if abs(a - self._start_level) <= s.on_level_band_m:  # came back: no change (a door, a gust, a step stool)
            self.moving = False
            self.level_m = self._start_level
            self._t_on_level = t
            self.counters["aborted_changes"] += 1
            return None
        if abs(rate) > s.settle_rate_m_s:
            self._settled_since = None
            return None
        if self._settled_since is None:
            self._settled_since = t
        if (t - self._settled_since) * 1e-9 < s.settle_s:
            return None
        t_end = self._settled_since
        delta = a - self._start_level
        speed = self._speed(self._start_level, delta, t_end)
        outdoors = self._good_fix_t is not None and self._good_fix_t >= self._t_start - _FIX_MARGIN_NS
        if speed < s.min_stairs_rate_m_s or outdoors:  # a ramp or a hill (or drift): not a floor change
            kind, n = "slope", 0
            self.carry_m = 0.0
        else:  # with the landing's altitude, so that two half-storey flights with a pause make a floor
            kind = "lift" if speed > s.lift_rate_m_s else "stairs"
            x = (delta + self.carry_m) / s.storey_height_m
            n = int(math.copysign(math.floor(abs(x) + 0.5 - s.round_margin), x))
            self.carry_m = 0.0 if n else delta + self.carry_m
            self._carry_t = t
        self.floor += n
        change = FloorChange(int(self._t_start), int(t_end), n, float(delta), float(speed), kind, self.floor)
        self.changes.append(change)
        self.moving = False
        self.level_m = a
        self._t_on_level = t
        return change

    def _speed(self, start: float, delta: float, t_end: int) -> float:
        """Vertical speed over the change's middle 80 % (10 % to 90 % of ``delta``), from the trace; the
        mean over the whole change when the trace does not hold it."""
        t10 = t90 = None
        t_from = self._t_start - _FIX_MARGIN_NS  # the change may have begun inside the level's band
        for tt, aa in self._trace:  # the last time below 10 % before the first time at 90 % (robust to a
            if tt < t_from:  # pressure transient on the level before the change)
                continue
            frac = (aa - start) / delta
            if frac < 0.1:
                t10 = tt
            elif t10 is not None and frac >= 0.9:
                t90 = tt
                break
        if t10 is None or t90 is None or t90 <= t10:
            return abs(delta) / max((t_end - self._t_start) * 1e-9, 1e-3)
        return 0.8 * abs(delta) / ((t90 - t10) * 1e-9)

    def note_fix(self, t_ns: int, hacc_m: float) -> None:
        """A GNSS fix with its horizontal accuracy (m): a good one means outdoors (see the module docstring)."""
        if math.isfinite(hacc_m) and hacc_m <= self.settings.outdoor_hacc_m:
            self._good_fix_t = int(t_ns)

    # -- batch ---------------------------------------------------------------------------------------
    def run(self, stream, gps=None) -> FloorResult:
        """The whole ``pressure`` stream through the kernel (see the class docstring); ``gps``: the
        recording's ``gps`` stream (its accuracy column says when the walk was outdoors), optional."""
        self.reset()
        t_all = np.asarray(stream.t_ns, dtype=np.int64)
        p_all = np.asarray(stream.values, dtype=float).reshape(len(t_all), -1)[:, 0]
        alt = np.full(len(t_all), math.nan)
        lev = np.full(len(t_all), math.nan)
        flo = np.zeros(len(t_all), dtype=int)
        fixes = []
        if gps is not None and len(gps.t_ns):
            fixes = list(zip(np.asarray(gps.t_ns, dtype=np.int64).tolist(), np.asarray(gps.values)[:, 3].tolist()))
        j = 0
        for k, (t, p) in enumerate(zip(t_all.tolist(), p_all.tolist())):
            while j < len(fixes) and fixes[j][0] <= t:
                self.note_fix(*fixes[j])
                j += 1
            skipped = self.counters["skipped"]
            self.update(t, p)
            if self.counters["skipped"] == skipped:
                alt[k], lev[k] = self.altitude_m, self.level_m
            flo[k] = self.floor
        return FloorResult(t_all, alt, lev, flo, list(self.changes), dict(self.counters))


__all__ = ["FloorChange", "FloorEstimator", "FloorResult", "FloorSettings", "altitude_m", "floors_at"]
