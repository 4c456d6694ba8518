"""Reader for the TrundleWheel app's raw logs (Jeremy618/TrundleWheel: phone web-API motion + a trundle wheel).

The authors' Cordova (web) app logs the phone's W3C DeviceMotion events
together with a sensorised trundle wheel that ticks every metre.

Format
======
Text (here also gzip), ``;``-separated, a header line naming the columns, then
one event a line with the other columns empty::

    time;o_alpha;o_beta;o_gamma;m_acc_x;...;m_accG_x;m_accG_y;m_accG_z;m_rotTate_alpha;m_rotTate_beta;
    m_rotTate_gamma;p_lat;p_long;p_alt;p_acc;p_head;p_speed;steps;distance;duration;date;total_distance;
    total_steps;device_os;device_model                                      (one line)

Columns are found by name; ``time`` and ``m_accG_x/y/z`` are required.

* ``time``: ms since the recording started, on the app's clock (arrival
  times of a web app: they jitter by a few ms).  ``t_ns = round(time * 1e6)``;
  absolute time is unknown.
* ``m_accG_*``: DeviceMotion ``accelerationIncludingGravity``, m/s^2 (0.1 m/s^2
  resolution, about 59 Hz).  Chrome on Android reports it in the Android
  device axes with the Android sign (flat, screen up: z = +g; checked on the
  still phone at the end of the real walks): the ``acc`` stream, copied.
* ``m_rotTate_alpha/beta/gamma``: DeviceMotion ``rotationRate`` in deg/s;
  W3C ``alpha`` is about z, ``beta`` about x, ``gamma`` about y: the ``gyro``
  stream is ``(beta, gamma, alpha)`` in rad/s.
* ``distance``: the trundle wheel's cumulative metres, one line per 1 m tick
  -- ground truth that is part of the file: the ``wheel`` stream
  (``distance_m``).
* ``steps``: the phone's own cumulative step-detector count, one line per
  step: the ``step_counts`` stream (column ``phone``).  The phone delivers
  steps in bursts, several lines with the same time (50 of the 488 lines of
  a real walk): the stream keeps the count after each burst (the last of
  consecutive lines with one time; so does ``wheel``).
* GNSS lines (``p_lat`` not empty) carry Unix-epoch times in ``time``, which
  cannot be tied to the app's clock: they are counted
  (``metadata["gnss_lines_skipped"]``), not read.  DeviceOrientation
  (``o_*``) and acceleration without gravity (``m_acc_*``) are not read.
* ``duration, date, total_distance, total_steps, device_os, device_model``
  are filled in the first line only: ``device`` and ``metadata``.

The authors' "conditioned" files
==================================
The same header without the ``o_*`` and bookkeeping columns, resampled by
the authors to one line a second with *every* field filled (``time`` on the
app's clock, ms).  A file whose lines carry acceleration and ``p_lat``
together is read as this layout (``metadata["layout"] = "conditioned"``;
raw GNSS lines never carry acceleration): ``acc`` and ``gyro`` at 1 Hz (one
sample a second: too coarse for step detection, which needs tens of Hz),
``gps`` from ``p_lat, p_long, p_alt, p_acc`` (horizontal accuracy, m),
``p_head`` (course, deg) and ``p_speed`` (m/s) of every line, ``wheel`` and
``step_counts`` from the (interpolated, cumulative) ``distance`` and
``steps``.  ``metadata["rate_warning"]`` says it, and so does a
:class:`LowRateWarning` when the acceleration comes at under
:data:`MIN_STEP_RATE_HZ` (a replay then finds no steps: the file's truth is
still shown).

There is no magnetometer.  A line with some but not all of a sensor's
fields, or a field that is not a number, is a bad line: skipped and counted,
or, past 100 or 1 % of the lines, a :class:`RecordingError` naming the first.
"""

from __future__ import annotations

import warnings

import numpy as np

from core.conventions import ACC, GPS, GYRO
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import (
    EXTRA_STREAM_SPECS, STEP_COUNTS, WHEEL, feed_lines, finish, first_bad_time, gps_check, gps_values, open_text,
)
from core.importers._csv import ColumnBuffer, fixed_rows

FORMAT = "trundlewheel"

REQUIRED = ["time", "m_accG_x", "m_accG_y", "m_accG_z"]
#: GNSS columns: latitude, longitude, altitude (m), horizontal accuracy (m), course (deg), speed (m/s)
GPS_COLUMNS = ["p_lat", "p_long", "p_alt", "p_acc", "p_head", "p_speed"]
GYRO_COLUMNS = ["m_rotTate_beta", "m_rotTate_gamma", "m_rotTate_alpha"]  # about x, y, z
#: below this acceleration rate (Hz) a step detector cannot work: a conditioned file says so in a warning
MIN_STEP_RATE_HZ = 10.0


class LowRateWarning(UserWarning):
    """The recording's acceleration is too coarse for step detection (the authors' 1 Hz resampled files)."""


#: the first line's facts
INFO = ("duration", "date", "total_distance", "total_steps", "device_os", "device_model")


def looks_like_csv(head: str) -> bool:
    """A raw log starts with a ``;``-separated header naming ``time`` and ``m_accG_x/y/z``."""
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip()
    names = [n.strip() for n in first.split(";")]
    return all(n in names for n in REQUIRED)


def _fill(lines: list[str]) -> list[str]:
    """The lines with ``nan`` in their empty fields (one event a line leaves most of them empty).

    Done on the chunk's text at once: each line between two added ``;``, every
    ``;;`` filled (twice: the replacements do not overlap), the added ``;``
    removed again.
    """
    s = ";" + ";\n;".join(lines) + ";"
    s = s.replace(";;", ";nan;").replace(";;", ";nan;")
    return s[1:-1].split(";\n;")


def read_trundle(path: str, *, warn: bool = True,
                 max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a raw TrundleWheel log (plain or gzip) into a :class:`Recording` (see the module doc).

    The file is streamed a chunk of lines at a time; a gzip stream inflating
    to over ``max_uncompressed_bytes`` is refused while it is read.
    """
    path = str(path)
    repairs: list[str] = []
    with open_text(path, repairs, max_uncompressed_bytes) as text, np.errstate(all="ignore"):
        reader = _Reader(path, repairs)
        feed_lines(text, path, repairs, reader.chunk, reader.bad, reader.tail)
        rec = reader.recording()
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=2)
        acc = rec.streams.get(ACC)
        if "rate_warning" in rec.metadata and acc is not None and len(acc) > 1 and acc.rate_hz < MIN_STEP_RATE_HZ:
            warnings.warn(f"{path}: acceleration at {acc.rate_hz:.1f} Hz -- {rec.metadata['rate_warning']}",
                          LowRateWarning, stacklevel=2)
    return finish(rec, warn=warn)


class _Reader:
    """The lines of a log, a chunk at a time, into the columns read (nan where a field is empty)."""

    def __init__(self, path: str, repairs: list[str]):
        self.path = path
        self.repairs = repairs
        self.header: list[str] | None = None
        self.first: list[str] | None = None  # the first data line's fields
        self.bad: list[RecordingError] = []
        self.n_lines = 0

    def _columns(self, line: str, lineno: int) -> None:
        self.header = [h.strip().strip('"') for h in line.split(";")]
        missing = [n for n in REQUIRED if n not in self.header]
        if missing:
            raise RecordingError(f"TrundleWheel raw log: missing column(s) {', '.join(missing)} (header: "
                                 f"{';'.join(self.header)[:300]})", self.path, lineno)
        want = {"acc": REQUIRED[1:], "gyro": GYRO_COLUMNS, "steps": ["steps"], "distance": ["distance"],
                "p_lat": ["p_lat"], "gps": GPS_COLUMNS[1:]}
        #: group -> the positions of its columns among the values read (the time is position 0)
        self.groups: dict[str, list[int]] = {}
        self.usecols = [self.header.index("time")]
        for name, cols in want.items():
            if all(c in self.header for c in cols):
                self.groups[name] = list(range(len(self.usecols), len(self.usecols) + len(cols)))
                self.usecols += [self.header.index(c) for c in cols]
        self.width = max(self.usecols) + 1
        self.values = ColumnBuffer(len(self.usecols))
        self.lines = ColumnBuffer(1, np.int64)

    def chunk(self, first: int, lines: list[str]) -> None:
        if self.header is None:
            k = next((i for i, ln in enumerate(lines) if ln.strip()), None)
            if k is None:
                return
            self._columns(lines[k], first + k)
            first, lines = first + k + 1, lines[k + 1:]
        nos = np.array([first + i for i, ln in enumerate(lines) if ln.strip()], dtype=np.int64)
        rows = [ln for ln in lines if ln.strip()]
        if not rows:
            return
        if self.first is None:
            self.first = rows[0].split(";")
        self.n_lines += len(rows)
        _, v, kept, errs = fixed_rows(_fill(rows), self.usecols, ";", (self.width, 1 << 30), int_first=False,
                                      names=self.header)
        self.bad.extend(RecordingError(msg, self.path, int(nos[j])) for j, msg in errs)
        self.values.append(v)
        self.lines.append(nos[kept][:, None])

    def tail(self, lineno: int, last: str) -> None:
        if last.strip():
            self.repairs.append(f"{self.path}: dropped an incomplete last line {lineno} (no newline: the log was cut "
                                "off mid-write)")

    def recording(self) -> Recording:
        if self.header is None:
            raise RecordingError("empty file", self.path)
        v, line = self.values.array(), self.lines.array()[:, 0]
        empty = np.isnan(v)
        g = self.groups
        gnss = ~empty[:, g["p_lat"][0]] if "p_lat" in g else np.zeros(len(v), dtype=bool)
        # the authors' resampled files: acceleration and GNSS on every line, all on the app's clock
        conditioned = bool(np.any(gnss & ~empty[:, g["acc"][0]]))
        if conditioned:
            gnss = np.zeros(len(v), dtype=bool)
        partial = np.zeros(len(v), dtype=bool)
        for name, cols in g.items():
            e = empty[:, cols]
            part = e.any(axis=1) & ~e.all(axis=1) & ~gnss
            for j in np.flatnonzero(part & ~partial):
                self.bad.append(RecordingError(f"missing fields: {name} needs {len(cols)} values", self.path,
                                               int(line[j])))
            partial |= part
        self.bad.sort(key=lambda err: err.line or 0)
        skip_bad_lines(self.bad, self.n_lines, self.path, self.repairs)
        use = ~gnss & ~partial
        j = first_bad_time(np.where(use, v[:, 0] * 1e-3, 0.0))
        if j is not None:
            raise RecordingError(f"'time' is not a usable time: {float(v[j, 0])!r}", self.path, int(line[j]))

        def rows(name, cumulative=False):
            ok = use & ~empty[:, g[name][0]]
            t, x = np.round(v[ok, 0] * 1e6).astype(np.int64), v[ok][:, g[name]]
            if cumulative and len(t):  # a burst of counts at one time: the count after it
                last = np.append(t[1:] != t[:-1], True)
                t, x = t[last], x[last]
            return t, x

        streams = {}
        t, a = rows("acc")
        if not len(t):
            raise RecordingError("no acceleration lines (m_accG_x/y/z all empty)", self.path)
        streams[ACC] = make_stream(ACC, t, a, note="W3C DeviceMotion accelerationIncludingGravity, 0.1 m/s^2 "
                                                   "resolution")
        if "gyro" in g:
            t, w = rows("gyro")
            streams[GYRO] = make_stream(GYRO, t, np.radians(w),
                                        note="W3C rotationRate (beta, gamma, alpha) converted to rad/s")
        if "distance" in g:
            t, d = rows("distance", cumulative=True)
            spec = EXTRA_STREAM_SPECS[WHEEL]
            streams[WHEEL] = make_stream(WHEEL, t, d, spec["columns"], spec["unit"],
                                         "ground truth: trundle-wheel distance (m), cumulative, one event a 1 m tick")
        if conditioned and "gps" in g:
            t, lat = rows("p_lat")
            o = use & ~empty[:, g["p_lat"][0]]
            lon, alt, hacc, course, speed = (v[o][:, c] for c in g["gps"])
            gv = gps_values(lat[:, 0], lon, alt, hacc, speed, course)
            streams[GPS] = make_stream(GPS, t, gv, note="GNSS of the authors' resampled file (1 Hz)")
        if "steps" in g:
            t, n = rows("steps", cumulative=True)
            spec = EXTRA_STREAM_SPECS[STEP_COUNTS]
            streams[STEP_COUNTS] = make_stream(STEP_COUNTS, t, n, ["phone"], spec["unit"],
                                               "the phone's own step detector, cumulative, one event a step")
        info = {k: self.first[self.header.index(k)].strip()[:200] for k in INFO
                if self.first is not None and k in self.header and self.header.index(k) < len(self.first)}
        os_name = info.get("device_os", "")
        device = {"platform": "ios" if os_name.lower().startswith("ios") else "android" if os_name else "",
                  "app": "TrundleWheel (web app, W3C DeviceMotion)", "model": info.get("device_model", ""),
                  "os_version": os_name}
        meta = {
            "source_format": FORMAT,
            "app": "TrundleWheel",
            "time_base": "t_ns = round(time * 1e6): ms since the recording started, the web app's clock (arrival "
                         "times); absolute time unknown",
            "layout": "conditioned" if conditioned else "raw",
            "gnss_lines_skipped": int(gnss.sum()),
            **{k: info[k] for k in ("duration", "date", "total_distance", "total_steps") if k in info},
        }
        if conditioned:
            meta["time_base"] = ("t_ns = round(time * 1e6): ms since the recording started, resampled by the "
                                 "authors to 1 Hz; absolute time unknown")
            meta["rate_warning"] = ("the authors' 1 Hz resampled file: one acceleration sample a second is too "
                                    "coarse for step detection; it carries walk-level truth (wheel distance, GPS)")
            if GPS in streams:
                meta["gps_check"] = gps_check(streams[GPS].t_ns, streams[GPS].values)
        return Recording(streams, device={k: x for k, x in device.items() if x}, metadata=meta,
                         repairs=self.repairs, source=self.path)
