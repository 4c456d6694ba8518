"""Every stream checked at the edge, once, with one vocabulary: what is wrong with a recording's streams.

Every reader (:func:`core.recording.read_recording` and :mod:`core.importers`) ends in
:func:`core.recording.repair_recording`, which calls :func:`validate_recording`: nothing past the reader
sees an impossible GPS fix, a GPS stream on another clock, or a GPS logger's flood.  What was found is a
:class:`Finding` in :attr:`core.recording.Recording.problems` (a :class:`StreamProblem`, the stream, a
count, what was done, one line of text); when something was changed its text is also a line of
:attr:`~core.recording.Recording.repairs` and a :class:`StreamProblemWarning`.  ``pdr replay`` prints them and counts
them in its JSON (``stream_problems``).

The checks of the values of the IMU streams against their units and of their clocks
(:func:`core.recording.check_values_against_units`, :func:`core.recording.check_time_base`) stay where they
are, in the reader: this module adds what needs the recording as a whole (one stream against the others).

Checks
======
GPS fixes (:data:`~core.conventions.GPS`)
    A fix with a latitude outside +-90 deg, a longitude outside +-180 deg or a negative accuracy is
    impossible: dropped and counted (``IMPOSSIBLE_FIX``).  When every fix is impossible the stream is left
    empty, so no origin, declination or evaluation comes from them.  A speed below 0 or beyond
    :data:`MAX_GPS_SPEED_M_S`, or a course outside 0-360 deg, is set unknown (nan), the fix kept
    (``IMPOSSIBLE_MOTION``).
Clocks (every stream that is not an IMU stream: GPS, GNSS status, ...)
    The IMU streams (acc, gyro, mag) share the sensor clock (the reader checks that they are nanoseconds).
    Another stream whose events lie outside the IMU's span (by more than the span, and at least a minute)
    is on another clock or in another unit: its timestamps times 1e3, 1e6 or 1e9 (us, ms, s) inside the
    IMU's span are repaired (``OTHER_TIME_UNIT``); Unix-epoch times with the recording's
    ``unix_offset_ns`` (Unix minus sensor clock) are moved to the sensor clock (``OTHER_CLOCK``); anything
    else is dropped with one line (the walk is read without it) rather than fused against the wrong time.
GPS rate
    Phone receivers give 1-10 fixes a second.  A stream faster than :data:`MAX_GPS_RATE_HZ` (a broken
    logger repeating fixes) is decimated to the first fix in every 1 / :data:`GPS_DECIMATE_HZ` s
    (``RATE_TOO_HIGH``), in time proportional to the walk.
Gaps (acc, gyro, mag)
    No events for over :data:`GAP_REPORT_S` (and :data:`JITTER_GAP_FACTOR` median intervals) is a gap
    (``GAP``), reported with its place.  A gap of the accelerometer while the gyroscope or the
    magnetometer ran says that no steps are measured across it: the pipeline estimates them where the
    gyroscope shows the walk went on (:mod:`core.pdr.gapbridge`), else the distance walked then is missing.
    Rates are computed without the gaps (:attr:`core.recording.Stream.rate_hz`).
Spikes (mag)
    ``|B|`` over :data:`MAG_SPIKE_UT` (four times the strongest Earth field) is a disturbance, not the
    Earth (``SPIKE``), reported with how long it lasted (the attitude filter's magnitude gate rejects those
    readings).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from enum import Enum

import numpy as np

from core.conventions import ACC, GPS, GYRO, MAG

#: the kinds on the sensor clock, checked by the reader (the reference for the other streams' clocks)
IMU_KINDS = (ACC, GYRO, MAG)
#: a GPS stream faster than this (fixes a second) is a broken logger (phones: 1-10 Hz) ...
MAX_GPS_RATE_HZ = 20.0
#: ... and is decimated to this rate (only streams of at least this many fixes are judged)
GPS_DECIMATE_HZ = 10.0
MIN_FIXES_FOR_RATE = 50
#: an IMU stream without events for longer than this (s) has a gap (reported) ...
GAP_REPORT_S = 1.0
#: ... when that is also over this many median intervals
JITTER_GAP_FACTOR = 2.5
#: a magnetometer reading beyond this (uT; the Earth's field is 25-65 uT) is a spike
MAG_SPIKE_UT = 260.0
#: a GPS speed beyond this (m/s; 1000 knots, the receivers' export limit) or below 0 is no receiver's
MAX_GPS_SPEED_M_S = 515.0
#: a stream's events outside the IMU's span by more than max(this, the span) are on another clock (s)
CLOCK_MARGIN_S = 60.0


class StreamProblem(Enum):
    """What can be wrong with a stream (the vocabulary of :class:`Finding`)."""

    IMPOSSIBLE_FIX = "impossible GPS fixes"
    IMPOSSIBLE_MOTION = "impossible GPS speed or course"
    OTHER_CLOCK = "on another clock"
    OTHER_TIME_UNIT = "timestamps in another unit"
    RATE_TOO_HIGH = "rate too high"
    RATE_TOO_LOW = "rate too low"
    GAP = "gap"
    SPIKE = "spike"
    NEGATIVE_TIMESTAMP = "negative timestamps"
    EMPTY = "no events"


class StreamProblemWarning(UserWarning):
    """A stream of a recording had a problem (:class:`Finding`); what was done is in its text."""


@dataclass(frozen=True)
class Finding:
    """One problem of one stream: ``count`` events (or stretches) concerned, ``action`` ``"repaired"``,
    ``"dropped"`` or ``"reported"``, ``text`` one line for the user."""

    problem: StreamProblem
    stream: str
    count: int
    action: str
    text: str

    def as_dict(self) -> dict:
        return {"problem": self.problem.name, "stream": self.stream, "count": self.count, "action": self.action,
                "text": self.text}


def problem_counts(findings) -> dict:
    """``{problem name: count}`` summed over ``findings`` (the JSON summary's ``stream_problems``)."""
    out: dict = {}
    for f in findings:
        out[f.problem.name] = out.get(f.problem.name, 0) + int(f.count)
    return out


def add_finding(rec, finding: Finding, warn: bool = True) -> None:
    """Note ``finding`` on ``rec``: its problems; when something was changed also its repairs and a warning
    (a finding only reported is in the problems, which ``pdr replay`` prints)."""
    rec.problems.append(finding)
    if finding.action != "reported":
        rec.repairs.append(finding.text)
        if warn:
            warnings.warn(finding.text, StreamProblemWarning, stacklevel=4)


def validate_recording(rec, warn: bool = True):
    """Check and repair the streams of ``rec`` in place (see the module docstring); returns ``rec``."""
    src = rec.source or "recording"
    if not any(len(s) for s in rec.streams.values()):
        return rec
    if GPS in rec.streams and len(rec.streams[GPS]):
        _impossible_fixes(rec, src, warn)
    if GPS in rec.streams and len(rec.streams[GPS]):
        _impossible_motion(rec, src, warn)
    span = _imu_span(rec)
    if span is not None:
        for name in list(rec.streams):
            if name.partition("@")[0] not in IMU_KINDS and len(rec.streams[name]):
                _check_clock(rec, name, span, src, warn)
    if GPS in rec.streams and len(rec.streams[GPS]) >= MIN_FIXES_FOR_RATE:
        _gps_rate(rec, src, warn)
    _gaps(rec, src, warn)
    if MAG in rec.streams:
        _mag_spikes(rec, src, warn)
    return rec


def _replace(rec, name, keep) -> None:
    from core.recording import Stream

    s = rec.streams[name]
    rec.streams[name] = Stream(s.name, s.t_ns[keep], s.values[keep], s.columns, s.unit, s.note)


def _impossible_fixes(rec, src, warn) -> None:
    v = rec.streams[GPS].values
    lat, lon, hacc = v[:, 0], v[:, 1], v[:, 3]
    with np.errstate(invalid="ignore"):
        bad = (np.abs(lat) > 90) | (np.abs(lon) > 180) | (hacc < 0)
    n = int(bad.sum())
    if not n:
        return
    k = int(np.flatnonzero(bad)[0])
    first = f"first: {lat[k]:.6g}, {lon[k]:.6g}" + (f", accuracy {hacc[k]:.3g} m" if hacc[k] < 0 else "")
    if n == len(v):
        text = (f"{src}: stream 'gps': all {n} fixes are impossible (latitude beyond +-90 deg, longitude beyond "
                f"+-180 deg or a negative accuracy; {first}): no GPS, and no origin or evaluation from them")
    else:
        text = (f"{src}: stream 'gps': dropped {n} impossible fix(es) of {len(v)} (latitude beyond +-90 deg, "
                f"longitude beyond +-180 deg or a negative accuracy; {first})")
    _replace(rec, GPS, ~bad)
    add_finding(rec, Finding(StreamProblem.IMPOSSIBLE_FIX, GPS, n, "dropped", text), warn)


def _impossible_motion(rec, src, warn) -> None:
    """A speed below 0 or beyond :data:`MAX_GPS_SPEED_M_S`, a course outside 0-360 deg: set unknown (nan), the
    fix's position kept (iOS writes -1 for "unknown"; the importers already read it so)."""
    s = rec.streams[GPS]
    v = np.array(s.values, dtype=np.float64)
    if v.shape[1] < 6:
        return
    speed, course = v[:, 4], v[:, 5]
    with np.errstate(invalid="ignore"):
        bad_s = (speed < 0) | (speed > MAX_GPS_SPEED_M_S)
        bad_c = (course < 0) | (course > 360)
    n = int(np.count_nonzero(bad_s | bad_c))
    if not n:
        return
    k = int(np.flatnonzero(bad_s | bad_c)[0])
    v[bad_s, 4] = np.nan
    v[bad_c, 5] = np.nan
    from core.recording import Stream

    rec.streams[GPS] = Stream(s.name, s.t_ns, v, s.columns, s.unit, s.note)
    text = (f"{src}: stream 'gps': {n} fix(es) of {len(v)} with an impossible speed or course (speed below 0 or "
            f"beyond {MAX_GPS_SPEED_M_S:g} m/s, course outside 0-360 deg; first: speed {speed[k]:.6g} m/s, course "
            f"{course[k]:.6g} deg): set unknown, their positions kept")
    add_finding(rec, Finding(StreamProblem.IMPOSSIBLE_MOTION, GPS, n, "repaired", text), warn)


def _imu_span(rec):
    spans = [(int(s.t_ns[0]), int(s.t_ns[-1])) for n, s in rec.streams.items()
             if n.partition("@")[0] in IMU_KINDS and len(s) > 1]
    if not spans:
        return None
    return min(a for a, _ in spans), max(b for _, b in spans)


def _inside(t0: float, t1: float, span, margin_ns: float) -> bool:
    return span[0] - margin_ns <= t0 and t1 <= span[1] + margin_ns


def _check_clock(rec, name, span, src, warn) -> None:
    from core.recording import Stream

    s = rec.streams[name]
    t0, t1 = float(s.t_ns[0]), float(s.t_ns[-1])
    margin = max(CLOCK_MARGIN_S * 1e9, float(span[1] - span[0]))
    if _inside(t0, t1, span, margin):
        return
    imu = f"the IMU's run from t_ns {span[0]} to {span[1]}"
    fixed = None
    for factor, unit in ((10**3, "microseconds"), (10**6, "milliseconds"), (10**9, "seconds")):
        if _inside(t0 * factor, t1 * factor, span, margin) and max(abs(t0), abs(t1)) * factor < 2 ** 62:
            fixed = s.t_ns * np.int64(factor)
            problem = StreamProblem.OTHER_TIME_UNIT
            text = (f"{src}: stream '{name}': its timestamps (t_ns {int(t0)} to {int(t1)}) are {unit}, not "
                    f"nanoseconds ({imu}): multiplied by {factor:.0e}")
            break
    off = rec.metadata.get("unix_offset_ns")
    if fixed is None and isinstance(off, int) and not isinstance(off, bool) and abs(off) < 2 ** 62:
        for factor, unit in ((1, "nanoseconds"), (10**3, "microseconds"), (10**6, "milliseconds"),
                             (10**9, "seconds")):
            a, b = t0 * factor - off, t1 * factor - off
            if _inside(a, b, span, margin) and max(abs(t0), abs(t1)) * factor < 2 ** 62:
                fixed = s.t_ns * np.int64(factor) - np.int64(off)
                problem = StreamProblem.OTHER_CLOCK
                text = (f"{src}: stream '{name}': its timestamps are Unix time in {unit}, not the sensor clock "
                        f"({imu}): moved to the sensor clock with the recording's unix_offset_ns")
                break
    if fixed is not None:
        rec.streams[name] = Stream(s.name, fixed, s.values, s.columns, s.unit, s.note)
        add_finding(rec, Finding(problem, name, len(s), "repaired", text), warn)
        return
    unix = 1e18 <= t0 <= 4e18
    why = ("Unix time in nanoseconds, and the recording has no unix_offset_ns to move it to the sensor clock"
           if unix else "neither nanoseconds on the sensor clock nor us, ms or s of it")
    text = (f"{src}: stream '{name}': its {len(s)} events (t_ns {int(t0)} to {int(t1)}) are not on the sensor "
            f"clock ({imu}; they look like {why}): the stream is dropped, the walk is read without it")
    _replace(rec, name, np.zeros(len(s), dtype=bool))
    add_finding(rec, Finding(StreamProblem.OTHER_CLOCK, name, len(s), "dropped", text), warn)


def _gps_rate(rec, src, warn) -> None:
    s = rec.streams[GPS]
    rate = s.rate_hz
    if not rate > MAX_GPS_RATE_HZ:
        return
    period = 1e9 / GPS_DECIMATE_HZ
    bins = np.floor((s.t_ns - s.t_ns[0]) / period).astype(np.int64)
    keep = np.ones(len(s), dtype=bool)
    keep[1:] = bins[1:] != bins[:-1]
    n = len(s)
    _replace(rec, GPS, keep)
    text = (f"{src}: stream 'gps': {n} fixes at {rate:.0f} Hz, faster than any phone receiver (at most "
            f"{MAX_GPS_RATE_HZ:g} Hz; a logger repeating fixes?): decimated to {GPS_DECIMATE_HZ:g} Hz, "
            f"{int(keep.sum())} fixes kept")
    add_finding(rec, Finding(StreamProblem.RATE_TOO_HIGH, GPS, n - int(keep.sum()), "repaired", text), warn)


def stream_gaps(t_ns, min_gap_s: float = GAP_REPORT_S, factor: float = JITTER_GAP_FACTOR):
    """``(start_ns, end_ns)`` arrays of the gaps of sorted timestamps: intervals over ``min_gap_s`` and over
    ``factor`` times the median interval."""
    t = np.asarray(t_ns, dtype=np.int64)
    if len(t) < 3:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    d = (t[1:] - t[:-1]).astype(np.float64)
    med = float(np.median(d))
    g = np.flatnonzero((d > min_gap_s * 1e9) & (d > factor * med))
    return t[g], t[g + 1]


def _ran_through(s, a: int, b: int) -> bool:
    """Whether stream ``s`` has at least half its usual events between ``a`` and ``b`` (ns): it ran in the gap."""
    inside = int(np.searchsorted(s.t_ns, b, side="left") - np.searchsorted(s.t_ns, a, side="right"))
    return inside >= max(1.0, 0.5 * (b - a) * 1e-9 * s.rate_hz)


def _gaps(rec, src, warn) -> None:
    t_ref = rec.t0_ns
    imu = {n: s for n, s in rec.streams.items() if n.partition("@")[0] in IMU_KINDS and len(s) > 2}
    for name, s in imu.items():
        a, b = stream_gaps(s.t_ns)
        if not len(a):
            continue
        k = int(np.argmax(b - a))
        longest = (b[k] - a[k]) * 1e-9
        others = [o for o, so in imu.items() if o != name and o.partition("@")[1:] == name.partition("@")[1:]
                  and _ran_through(so, int(a[k]), int(b[k]))]
        where = f"{(a[k] - t_ref) * 1e-9:.1f} s to {(b[k] - t_ref) * 1e-9:.1f} s"
        text = (f"{src}: stream '{name}': {len(a)} gap(s) without events, the longest {longest:.1f} s "
                f"({where} after the start)")
        if others:
            text += f" while {' and '.join(others)} ran"
        if name.partition("@")[0] == ACC:
            if any(o.partition("@")[0] == GYRO for o in others):
                text += (": no steps are measured across it; where the gyroscope shows the walk went on the pipeline "
                         "estimates them (see its labels), else the distance walked in it is missing")
            else:
                text += ": no steps are counted across a gap (the distance walked in it is missing)"
        text += "; rates are computed without the gaps"
        add_finding(rec, Finding(StreamProblem.GAP, name, len(a), "reported", text), warn)


def _mag_spikes(rec, src, warn) -> None:
    s = rec.streams[MAG]
    if not len(s):
        return
    with np.errstate(invalid="ignore"):
        norm = np.linalg.norm(s.values, axis=1)
        over = norm > MAG_SPIKE_UT
    n = int(over.sum())
    if not n:
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], over.astype(np.int8), [0]])))
    starts, ends = edges[::2], edges[1::2] - 1
    dur = (s.t_ns[ends] - s.t_ns[starts]) * 1e-9
    k = int(np.argmax(dur))
    text = (f"{src}: stream 'mag': {n} reading(s) beyond {MAG_SPIKE_UT:g} uT (the Earth's field is 25-65 uT) in "
            f"{len(starts)} stretch(es), the longest {dur[k]:.1f} s from {(s.t_ns[starts[k]] - rec.t0_ns) * 1e-9:.1f} s"
            f" after the start, up to {float(np.nanmax(norm)):.0f} uT: a magnetic disturbance, not the Earth's "
            "field (the heading filter does not use them)")
    add_finding(rec, Finding(StreamProblem.SPIKE, MAG, n, "reported", text), warn)


def low_rate_finding(rec, name: str, need_hz: float, what: str) -> Finding | None:
    """A ``RATE_TOO_LOW`` finding when stream ``name`` runs below ``need_hz`` (``what`` needs it), or None."""
    s = rec.streams.get(name)
    if s is None or len(s) < 3:
        return None
    rate = s.rate_hz
    if rate >= need_hz:
        return None
    text = (f"{rec.source or 'recording'}: stream '{name}' runs at {rate:.1f} Hz: {what} needs at least "
            f"{need_hz:g} Hz")
    return Finding(StreamProblem.RATE_TOO_LOW, name, len(s), "reported", text)


def gap_free_rate_hz(t_ns) -> float:
    """Events a second over the stream without its gaps (:func:`stream_gaps`); 0 for fewer than two events."""
    t = np.asarray(t_ns, dtype=np.int64)
    if len(t) < 2:
        return 0.0
    total = float(t[-1] - t[0])
    a, b = stream_gaps(t)
    n = len(t) - 1 - len(a)
    busy = total - float(np.sum(b - a))
    if busy <= 0 or n <= 0:
        return (len(t) - 1) / total * 1e9 if total > 0 else 0.0
    return n / busy * 1e9


__all__ = ["StreamProblem", "Finding", "StreamProblemWarning", "validate_recording", "problem_counts",
           "low_rate_finding", "gap_free_rate_hz", "stream_gaps"]
