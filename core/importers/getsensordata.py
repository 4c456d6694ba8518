"""Reader for GetSensorData logfiles (LOPSI / CAR-CSIC Android app; IPIN competition logs).

Format
======
Plain text (here also gzip), ``%`` comment lines (a header naming the phone
and the record formats), then one ``;``-separated record per line in arrival
order.  The records read here (field 0 is the tag)::

    ACCE;AppTimestamp(s);SensorTimestamp(s);Acc_X(m/s^2);Acc_Y;Acc_Z;Accuracy
    GYRO;AppTimestamp(s);SensorTimestamp(s);Gyr_X(rad/s);Gyr_Y;Gyr_Z;Accuracy
    MAGN;AppTimestamp(s);SensorTimestamp(s);Mag_X(uT);Mag_Y;Mag_Z;Accuracy
    AHRS;AppTimestamp(s);SensorTimestamp(s);PitchX(deg);RollY(deg);YawZ(deg);Quat(2);Quat(3);Quat(4);Accuracy
    PRES;AppTimestamp(s);SensorTimestamp(s);Pres(mbar);Accuracy
    GNSS;AppTimestamp(s);SensorTimeStamp(s);Latit(deg);Long(deg);Altitude(m);Bearing(deg);Accuracy(m);
         Speed(m/s);SatInView;SatInUse                                              (one line)
    POSI;Timestamp(s);Counter;Latitude(deg);Longitude(deg);FloorID;BuildingID

Every other record type (WIFI, BLE4, LIGH, SOUN, PROX, ...) is counted in
``metadata["ignored_line_types"]``, not read.  Fields after the ones used
(``Accuracy``, trailing ``;``) are ignored; fewer fields than needed, or a
field that is not a number, is a bad line: skipped and counted, or, past 100
or 1 % of the lines, a :class:`RecordingError` naming the first.

Time base (established on the 32 IPIN 2023 logfiles of ``../shared/data``)
=========================================================================
* ``SensorTimestamp`` is ``SensorEvent.timestamp`` in seconds (0.1 ms
  resolution): one clock for ACCE, GYRO, MAGN, AHRS, PRES and LIGH
  (``SensorTimestamp - AppTimestamp`` agrees across them to about 1 ms),
  strictly increasing within each inertial stream (no repeats, nothing going
  backwards) and without drift against ``AppTimestamp`` (< 1 ms over 4 min).
  Its differences are the true sampling intervals, so it is the time base:
  ``t_ns = round(SensorTimestamp * 1e9)`` -- not shifted, so ``t_ns`` is
  Android's ``elapsedRealtimeNanos`` clock (seconds since boot).
* ``AppTimestamp`` (seconds since the app started logging) is when the app
  *received* an event.  POSI lines carry only this clock, and GNSS lines
  carry it as their only phone-clock time.  They are mapped onto the sensor
  clock with ``t_ns = AppTimestamp * 1e9 + app_to_sensor_offset_ns``, the
  offset being the 99th percentile of ``SensorTimestamp - AppTimestamp``
  over the inertial records (the events delivered with the least latency);
  the mapping is good to about 1-5 ms.
* the GNSS ``SensorTimeStamp`` is **not** the sensor clock: it is the fix
  time ``Location.getTime()`` in Unix seconds (UTC; whole seconds on the
  SM-A520F).  It gives absolute time: ``metadata["unix_offset_ns"]`` with
  ``unix_ns = t_ns + unix_offset_ns`` (about +-1 s).  Without GNSS the header
  line ``% Date of creation: ...`` (phone wall clock, 1 s resolution, taken
  as AppTimestamp 0) is used instead.  In the IPIN files the header time is
  19-20 s *behind* the GNSS time on the SM-A520F (18 s is the GPS-UTC leap
  second count: that phone may report GPS time, or its clock was off) and
  220-222 s *ahead* on the SM-G930F (a wall clock minutes off); both are in
  ``metadata["phone_clock_minus_gnss_s"]``.
* every GNSS fix is logged twice (two consecutive lines, same fix time,
  a few ms apart); the repeat is dropped.

Units and axes
==============
ACCE (m/s^2, gravity included), GYRO (rad/s) and MAGN (uT, calibrated) are
Android ``SensorEvent.values`` in the Android device frame: copied as they
are.  PRES is hPa (mbar) -> stream ``pressure``.

Attitude (AHRS)
===============
AHRS is Android's ``TYPE_ROTATION_VECTOR``: ``Quat(2..4)`` are
``values[0..2]`` = the vector part ``(x, y, z)`` of the unit quaternion
rotating device vectors into East-North-Up, the scalar part is not logged and
is restored as ``w = sqrt(1 - x^2 - y^2 - z^2)`` (Android's own
``getQuaternionFromVector`` convention, ``w >= 0``).  The three angles are
Z-X-Y Euler angles of the same rotation, ``R = Rz(YawZ) Rx(PitchX) Ry(RollY)``:
``PitchX = asin(R[2,1])`` (top edge up is positive), ``RollY =
atan2(-R[2,0], R[2,2])``, ``YawZ = atan2(-R[0,1], R[1,1])`` -- i.e. **YawZ is
minus the Android azimuth** (counter-clockwise from magnetic North), and
PitchX is minus Android's pitch.  Verified on the IPIN files: the angles
recomputed from the quaternion match the logged ones on every line (median
1e-5 deg, at most 0.16 deg: the 6-decimal rounding near pitch +-90 deg), the
quaternion turns the accelerometer's up vector to ENU up (median 1-3 deg,
motion included), and its heading matches the tilt-compensated magnetometer
heading within 1-3 deg (median) while the walker stands.  The ``rotvec``
stream is ``(w, x, y, z)`` ENU<-device (the convention of :mod:`core`);
lines without quaternion fields are converted from the angles.

GNSS
====
The header documents ``GNSS;AppTimestamp(s);SensorTimeStamp(s);Latit(deg);
Long(deg);Altitude(m);Bearing(deg);Accuracy(m);Speed(m/s);SatInView;SatInUse``
and all 32 IPIN logfiles have these 11 fields on every GNSS line (Speed in
0.1 m/s steps, Bearing with 3 decimals).  The app logs
``Location.getBearing()`` unconditionally: a Bearing of exactly 0 is
Android's "no bearing" (nan; 2728 of the 9912 IPIN lines, 98 % of them with
a speed of 0, none above 0.6 m/s); a speed of 0 is kept.
Lines without the Speed field read it as nan.
``SatInView`` and ``SatInUse`` become the ``gnss_status`` stream at each kept
fix's time, columns ``n_used, cn0_4th_dbhz, n_view`` (no C/N0 is logged: nan),
when a line has them.  On the IPIN tuning routes (file medians) the SM-A520F
uses 21-23 of 24-25 satellites in view on the ground floor (routes 01-02) and
7-14 of 11-17 on level -2, the SM-G930F 9-12 of 15-16 and 4-7 of 7-12; some
fixes report 0 in use (the C/N0 rule of :mod:`core.gnss.base` refuses fewer
than 4).  The IPIN walks are indoors:
the speeds there are receiver noise (median 0-0.6 m/s), not walking.

Streams: ``acc``, ``gyro``, ``mag``, ``rotvec``, ``gps`` (from GNSS: lat_deg,
lon_deg, alt_m, hacc_m = the ``Accuracy(m)`` field, speed_m_s = ``Speed``,
course_deg = ``Bearing``; ``metadata["gps_check"]`` compares the last two
with the fixes' track), ``gnss_status`` (the satellites, above), ``pressure`` and
``posi`` (lat_deg, lon_deg, floor, building_id, counter: the surveyed
ground-truth landmarks), each only when the file has such lines.
"""

from __future__ import annotations

import re
import warnings
from datetime import datetime

import numpy as np

from core import quaternion as quat
from core.conventions import ACC, GNSS_STATUS, GPS, GYRO, MAG, ROTVEC
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, WholeText, make_stream, skip_bad_lines,
)
from core.importers._common import (
    EXTRA_STREAM_SPECS, POSI, PRESSURE, attitude_checks, feed_lines, finish, first_bad_time, gps_check, gps_values,
    magnetic_dip_deg, open_text,
)
from core.importers._csv import BadRow, ColumnBuffer, number, parse_rows

FORMAT = "getsensordata"

#: tag -> (names of the fields after the tag that are read, number of them that are required)
RECORDS: dict[str, tuple[tuple[str, ...], int]] = {
    "ACCE": (("AppTimestamp", "SensorTimestamp", "Acc_X", "Acc_Y", "Acc_Z", "Accuracy"), 5),
    "GYRO": (("AppTimestamp", "SensorTimestamp", "Gyr_X", "Gyr_Y", "Gyr_Z", "Accuracy"), 5),
    "MAGN": (("AppTimestamp", "SensorTimestamp", "Mag_X", "Mag_Y", "Mag_Z", "Accuracy"), 5),
    "AHRS": (("AppTimestamp", "SensorTimestamp", "PitchX", "RollY", "YawZ", "Quat(2)", "Quat(3)", "Quat(4)"), 5),
    "PRES": (("AppTimestamp", "SensorTimestamp", "Pres"), 3),
    "GNSS": (("AppTimestamp", "SensorTimeStamp", "Latitude", "Longitude", "Altitude", "Bearing", "Accuracy",
              "Speed", "SatInView", "SatInUse"), 7),
    "POSI": (("Timestamp", "Counter", "Latitude", "Longitude", "FloorID", "BuildingID"), 4),
}

POSI_SPEC = {
    "columns": ["lat_deg", "lon_deg", "floor", "building_id", "counter"],
    "unit": "deg,deg,1,1,1",
    "note": "ground-truth landmark (GetSensorData POSI): surveyed point the walker stepped on",
}

#: the ``gnss_status`` stream of the GNSS lines: the satellites in use and in view at each fix (no C/N0 is logged)
STATUS_COLUMNS = ("n_used", "cn0_4th_dbhz", "n_view")
STATUS_UNIT = "1,dB-Hz,1"
STATUS_NOTE = ("GNSS receiver status at a fix (GetSensorData GNSS SatInUse, SatInView: Android Location extras); "
               "no C/N0 logged (nan)")

#: a line starting like a GetSensorData record (for format detection)
RECORD_RE = re.compile(r"^(ACCE|GYRO|MAGN|AHRS|PRES|GNSS|POSI|LIGH|SOUN|WIFI|BLE4|PROX);[-0-9.]", re.M)


def looks_like(head: str) -> bool:
    """True if the start of a text file looks like a GetSensorData logfile."""
    if "GetSensorData" in head[:4096] and head.lstrip().startswith("%"):
        return True
    return len(RECORD_RE.findall(head)) >= 3


def read_getsensordata(path: str, *, warn: bool = True,
                       max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a GetSensorData logfile (plain or gzip) into a :class:`Recording` (see the module doc).

    The file is streamed a chunk of lines at a time; a gzip stream inflating
    to over ``max_uncompressed_bytes`` is refused while it is read.
    """
    path = str(path)
    with open_text(path, [], max_uncompressed_bytes) as text, np.errstate(all="ignore"):
        return _parse(text, path, warn, [])


class _Lines:
    """One chunk of the file's lines, with the lookup of a record's line number for messages (errors only)."""

    def __init__(self, lines: list[str], source: str, first: int = 1):
        self.lines = lines
        self.source = source
        self.first = first

    def lineno(self, tag: str, j: int) -> int:
        prefix = tag + ";"
        k = -1
        for i, line in enumerate(self.lines):
            if line.startswith(prefix):
                k += 1
                if k == j:
                    return self.first + i
        return self.first + len(self.lines) - 1

    def error(self, tag: str, j: int, message: str) -> RecordingError:
        return RecordingError(message, self.source, self.lineno(tag, j))


def _table(tag: str, rows: list[str]) -> tuple[np.ndarray, np.ndarray, list[tuple[int, str]]]:
    """The numeric fields of one record type: ``(table, kept, bad)``.

    ``table`` is (rows kept, len(names)) float64, optional missing fields
    nan; ``kept`` marks the rows kept; ``bad`` lists ``(row, message)`` for
    each row with fields missing or not numbers.  Parsing is numpy's C
    ``loadtxt`` on the rows of one record type and one field count (about
    6 million numbers a second); a row it refuses is looked at in Python.
    """
    names, required = RECORDS[tag]
    want = len(names)
    n = len(rows)
    # fields after the tag, capped at the ones read
    have = np.fromiter((r.count(";") for r in rows), dtype=np.int64, count=n)
    kept = have >= required
    bad = [(int(j), _missing_msg(tag, int(have[j]))) for j in np.flatnonzero(~kept)]
    have = np.minimum(have, want)
    out = np.full((n, want), np.nan)
    for k in np.unique(have[kept]):
        idx = np.flatnonzero((have == k) & kept)
        sub = rows if len(idx) == n else [rows[i] for i in idx]

        def slow(j, sub=sub, k=int(k)):
            f = sub[j].split(";")[1:1 + k]
            vals = []
            for c, v in enumerate(f):
                try:
                    vals.append(number(v))
                except ValueError:
                    raise BadRow(f"{tag} field {c + 2} ({names[c]}) is not a number: {v[:40]!r}") from None
            return vals, [False] * k

        _, vals, _, ok, b = parse_rows(sub, list(range(1, 1 + int(k))), ";", slow)
        out[idx[ok], :int(k)] = vals[ok]
        kept[idx[~ok]] = False
        bad += [(int(idx[j]), msg) for j, msg in b]
    bad.sort()
    return out[kept], kept, bad


def _missing_msg(tag: str, have: int) -> str:
    names, required = RECORDS[tag]
    return (f"missing fields: {tag} needs {required} fields after the tag "
            f"({';'.join(names[:required])}), found {have}")


def _parse_header(comments: list[str]) -> tuple[dict, dict]:
    device: dict = {"platform": "android"}
    meta: dict = {}
    keys = {"manufacturer": "manufacturer", "model": "model", "api android version": "android_api",
            "android version release": "os_version"}
    for line in comments:
        body = line.lstrip("%").strip()
        m = re.match(r"([A-Za-z ]+):\s*(.*)$", body)
        if m and m.group(1).strip().lower() in keys:
            key = keys[m.group(1).strip().lower()]
            val = m.group(2).strip()
            device[key] = int(val) if key == "android_api" and val.isdigit() else val
        elif body.startswith("Date of creation:"):
            meta["header_date"] = body.split(":", 1)[1].strip()
        else:
            m = re.match(r"Version\s+([0-9][0-9.]*)", body)
            if m:
                meta["app_version"] = m.group(1)
    return device, meta


def _header_unix_s(date: str) -> int | None:
    """'Wed Jun 14 10:00:58 GMT+02:00 2023' -> Unix seconds (None if it does not parse)."""
    m = re.match(r"\w{3} (\w{3}) (\d{1,2}) (\d\d):(\d\d):(\d\d) (?:GMT|UTC)?([+-]\d\d):?(\d\d) (\d{4})", date.strip())
    if not m:
        return None
    months = ["Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"]
    if m.group(1) not in months:
        return None
    try:
        sign = 1 if m.group(6)[0] == "+" else -1
        tz = f"{'+' if sign > 0 else '-'}{m.group(6)[1:]}{m.group(7)}"
        dt = datetime.strptime(f"{m.group(8)}-{months.index(m.group(1)) + 1:02d}-{int(m.group(2)):02d} "
                               f"{m.group(3)}:{m.group(4)}:{m.group(5)} {tz}", "%Y-%m-%d %H:%M:%S %z")
    except ValueError:
        return None
    return int(dt.timestamp())


def _robust_high(d_ns: np.ndarray, pct: float, overwrite: bool = False) -> int:
    """The ``pct`` percentile of int64 nanosecond values, exact (no float rounding of ~1e18 values).

    With ``overwrite`` ``d_ns`` is used as scratch space (no copy of it).
    """
    base = int(d_ns.min())
    if overwrite:
        d_ns -= base
        return base + int(round(float(np.percentile(d_ns, pct, overwrite_input=True))))
    return base + int(round(float(np.percentile(d_ns - base, pct))))


def _sec_to_ns(s: np.ndarray) -> np.ndarray:
    x = s * 1e9
    return np.rint(x, out=x).astype(np.int64)


#: AHRS rows converted to quaternions at a time (the conversion's temporaries are a few of these)
_AHRS_BLOCK = 1 << 16


def _ahrs_quaternions(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """AHRS rows -> ``(q (n, 4) ENU<-device, has_vec (n,), angle between the angles' and the vector's q (deg))``.

    The quaternion is the logged rotation vector where there is one, else
    the one of the angles; converted a block of rows at a time.
    """
    n = len(v)
    q = np.empty((n, 4))
    has_vec = np.all(np.isfinite(v[:, 5:8]), axis=1)
    ang = np.empty(int(has_vec.sum()))
    k = 0
    for a in range(0, n, _AHRS_BLOCK):
        b = v[a:a + _AHRS_BLOCK]
        pitch, roll, yaw = (np.radians(b[:, c]) for c in (2, 3, 4))
        # R = Rz(yaw) Rx(pitch) Ry(roll)  <=>  q = qz(yaw) (x) qx(pitch) (x) qy(roll)
        q_angles = quat.multiply_array(quat.multiply_array(quat.about_axis_array(2, yaw),
                                                           quat.about_axis_array(0, pitch)),
                                       quat.about_axis_array(1, roll))
        q_angles = quat.canonical_sign_array(q_angles)
        hv = has_vec[a:a + _AHRS_BLOCK]
        q[a:a + len(b)] = q_angles
        if hv.any():
            xyz = b[hv, 5:8]
            # the rotation vector's scalar part is not logged: w = sqrt(1 - |xyz|^2) >= 0 (Android's convention);
            # |xyz|^2 exceeds 1 by ~1e-7 in real files, hence the clip and the renormalisation
            w = np.sqrt(np.clip(1.0 - np.einsum("ij,ij->i", xyz, xyz), 0.0, None))
            qv = np.column_stack([w, xyz])
            qv /= np.linalg.norm(qv, axis=1, keepdims=True)
            q[a + np.flatnonzero(hv)] = qv
            dot = np.abs(np.einsum("ij,ij->i", qv, q_angles[hv]))
            ang[k:k + len(qv)] = np.degrees(2.0 * np.arccos(np.clip(dot, -1.0, 1.0)))
            k += len(qv)
    return q, has_vec, ang


def parse_getsensordata(text: str, source: str = "<text>", *, warn: bool = True,
                        _repairs: list[str] | None = None) -> Recording:
    """Parse the text of a GetSensorData logfile (see the module doc).

    Damage that is repaired, each with a line in ``repairs`` and a
    :class:`core.recording.DamagedFileWarning`: a gzip stream cut part-way
    (the part before the damage is read), a last line without its newline
    (dropped even when it parses), and bad record lines (fields missing or
    not numbers) when they are at most 100 and at most 1 % of the lines
    (:func:`core.recording.bad_lines_tolerated`; beyond that a
    :class:`RecordingError` names the first).
    """
    # times are validated explicitly; non-finite sensor values pass through as data, without numpy warnings
    with np.errstate(all="ignore"):
        return _parse(WholeText(text), source, warn, list(_repairs or []))


#: distinct record types counted in ``metadata["line_counts"]``; more are counted as "(other)"
MAX_LINE_TYPES = 1000
#: comment lines kept for the header (it is at the top of the file)
MAX_COMMENTS = 1000


def _parse(text, source: str, warn: bool, repairs: list[str]) -> Recording:
    """The records of a logfile's lines (:class:`core.recording.TextLines` or ``WholeText``), a chunk at a time.

    Only the numbers of the records read are kept, in growing arrays (a
    record type's fields: 8 bytes each); other lines are counted.
    """
    comments: list[str] = []
    counts: dict[str, int] = {}  # lines per record type, in order of appearance
    buffers: dict[str, ColumnBuffer] = {}
    bad: list[RecordingError] = []
    bad_time: dict[str, RecordingError] = {}  # the first record of each type whose time is not usable

    def chunk(first: int, lines: list[str]) -> None:
        buckets: dict[str, list[str]] = {}
        for line in lines:
            if not line or line[0] == "%":
                if line and len(comments) < MAX_COMMENTS:
                    comments.append(line)
                continue
            key = line[:5]
            b = buckets.get(key)
            if b is None:
                buckets[key] = [line]
            else:
                b.append(line)
        # regroup by the real tag (field 0); almost every key is already "TAG;"
        records: dict[str, list[str]] = {}
        for key, rows in buckets.items():
            if len(key) == 5 and key[4] == ";":
                records.setdefault(key[:4], []).extend(rows)
            else:
                for r in rows:
                    tag = r.partition(";")[0].strip()[:16]  # a stray text line counts under its first 16 characters
                    if tag:
                        records.setdefault(tag, []).append(r)
        ctx = _Lines(lines, source, first)
        for tag, rows in records.items():
            if tag not in counts and len(counts) >= MAX_LINE_TYPES and tag not in RECORDS:
                tag = "(other)"
            counts[tag] = counts.get(tag, 0) + len(rows)
            if tag not in RECORDS:
                continue
            table, kept, errs = _table(tag, rows)
            bad.extend(ctx.error(tag, j, msg) for j, msg in errs)
            if not len(table):
                continue
            if tag not in buffers:
                buffers[tag] = ColumnBuffer(len(RECORDS[tag][0]))
            buffers[tag].append(table)
            if tag not in bad_time:
                names = RECORDS[tag][0]
                for c in ((0,) if tag in ("GNSS", "POSI") else (0, 1)):  # the columns used as times
                    j = first_bad_time(table[:, c])
                    if j is not None:
                        bad_time[tag] = ctx.error(tag, int(np.flatnonzero(kept)[j]),
                                                  f"{tag} {names[c]} is not a usable time: {float(table[j, c])!r}")
                        break

    def tail(lineno: int, last: str) -> None:
        # a last line without its newline: the logger was cut off; dropped even when it parses ("2.586e-0" may be
        # a cut "2.586e-05")
        if last[0] != "%" and last.partition(";")[0] in RECORDS:
            repairs.append(f"{source}: dropped an incomplete last line {lineno} (logging was cut off)")
        else:
            chunk(lineno, [last])

    feed_lines(text, source, repairs, chunk, bad, tail)
    bad.sort(key=lambda e: e.line or 0)
    skip_bad_lines(bad, sum(counts.values()), source, repairs)
    tables = {tag: b.array() for tag, b in buffers.items()}
    for tag in counts:  # in the order the record types first appear
        if tag in bad_time:
            raise bad_time[tag]
    counts = dict(sorted(counts.items()))
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=3)
    if not any(t in tables for t in ("ACCE", "GYRO", "MAGN", "AHRS")):
        raise RecordingError("no ACCE, GYRO, MAGN or AHRS records: not a GetSensorData logfile, or an empty one",
                             source)

    device, meta = _parse_header(comments)
    streams = {}
    # -- inertial streams: SensorTimestamp is the time base; values are Android's, copied unchanged
    for tag, name in (("ACCE", ACC), ("GYRO", GYRO), ("MAGN", MAG)):
        if tag in tables:
            v = tables[tag]
            streams[name] = make_stream(name, _sec_to_ns(v[:, 1]), v[:, 2:5])
    if "PRES" in tables:
        v = tables["PRES"]
        spec = EXTRA_STREAM_SPECS[PRESSURE]
        streams[PRESSURE] = make_stream(PRESSURE, _sec_to_ns(v[:, 1]), v[:, 2:3], spec["columns"], spec["unit"],
                                        spec["note"])
    # -- AppTimestamp -> sensor clock
    clock_tags = [t for t in ("ACCE", "GYRO", "MAGN", "AHRS", "PRES") if t in tables]
    offs = np.empty(sum(len(tables[t]) for t in clock_tags), dtype=np.int64)
    k = 0
    for t in clock_tags:
        offs[k:k + len(tables[t])] = _sec_to_ns(tables[t][:, 1])
        offs[k:k + len(tables[t])] -= _sec_to_ns(tables[t][:, 0])
        k += len(tables[t])
    app_offset_ns = _robust_high(offs, 99, overwrite=True)
    del offs
    meta["app_to_sensor_offset_ns"] = app_offset_ns

    def app_to_t_ns(app_s):
        return _sec_to_ns(app_s) + app_offset_ns

    # -- attitude: Android rotation vector -> ENU<-device quaternion (w, x, y, z)
    if "AHRS" in tables:
        v = tables["AHRS"]
        t_rot = _sec_to_ns(v[:, 1])
        q, has_vec, ang = _ahrs_quaternions(v)
        if has_vec.any():
            meta["ahrs_angles_vs_quaternion_deg"] = {"median": float(np.median(ang)), "max": float(np.max(ang))}
        meta["ahrs_from_angles"] = int((~has_vec).sum())
        streams[ROTVEC] = make_stream(ROTVEC, t_rot, q,
                                      note="Android rotation vector (GetSensorData AHRS) as an ENU<-device "
                                           "quaternion (w, x, y, z); heading relative to magnetic north")

    # -- GNSS: received at AppTimestamp; the logged 'SensorTimeStamp' is the fix time in Unix seconds
    unix_offset_ns = None
    if "GNSS" in tables:
        v = tables["GNSS"]
        keep = np.ones(len(v), dtype=bool)
        # each fix is logged twice in a row: same fix time and position
        keep[1:] = ~((v[1:, 1] == v[:-1, 1]) & (v[1:, 2] == v[:-1, 2]) & (v[1:, 3] == v[:-1, 3]))
        meta["gnss_repeats_dropped"] = int((~keep).sum())
        v = v[keep]
        t_gps = app_to_t_ns(v[:, 0])
        streams[GPS] = make_stream(GPS, t_gps, gps_values(v[:, 2], v[:, 3], v[:, 4], v[:, 6], v[:, 7], v[:, 5]),
                                   note="GNSS fix (GetSensorData GNSS), time of reception; hacc_m = Android "
                                        "Location accuracy (68 %); speed_m_s = Speed(m/s) (0.1 m/s steps), "
                                        "course_deg = Bearing(deg) (exactly 0 = Android's 'no bearing' = nan)")
        meta["gps_check"] = gps_check(t_gps, streams[GPS].values)
        sats = v[:, 8:10]  # SatInView, SatInUse (nan where the line stops before them)
        if np.isfinite(sats[:, 1]).any():
            streams[GNSS_STATUS] = make_stream(GNSS_STATUS, t_gps, np.column_stack([sats[:, 1], np.full(len(v), np.nan),
                                                                                    sats[:, 0]]),
                                               STATUS_COLUMNS, STATUS_UNIT, STATUS_NOTE)
        fix_ok = np.isfinite(v[:, 1]) & (v[:, 1] > 1e9) & (v[:, 1] < 1e10)  # a Unix time after 2001
        if fix_ok.sum() >= 1:
            d = _sec_to_ns(v[fix_ok, 1]) - t_gps[fix_ok]
            # a fix is received after it was computed, so the largest differences have the least latency
            unix_offset_ns = _robust_high(d, 90)
            meta["unix_time_source"] = "GNSS fix times (Location.getTime, UTC) against their reception; about +-1 s"
    header_unix = _header_unix_s(meta.get("header_date", "")) if "header_date" in meta else None
    if header_unix is not None:
        header_offset_ns = header_unix * 1_000_000_000 - app_offset_ns  # the header time is AppTimestamp 0
        if unix_offset_ns is None:
            unix_offset_ns = header_offset_ns
            meta["unix_time_source"] = "header 'Date of creation' (phone wall clock, 1 s resolution)"
        else:
            meta["phone_clock_minus_gnss_s"] = round((header_offset_ns - unix_offset_ns) * 1e-9, 3)

    # -- POSI: ground-truth landmarks, AppTimestamp clock
    if "POSI" in tables:
        v = tables["POSI"]
        vals = np.column_stack([v[:, 2], v[:, 3], v[:, 4], v[:, 5], v[:, 1]])
        streams[POSI] = make_stream(POSI, app_to_t_ns(v[:, 0]), vals, POSI_SPEC["columns"], POSI_SPEC["unit"],
                                    POSI_SPEC["note"])

    if "MAGN" in tables:
        acc_levels = tables["MAGN"][:, 5]
        lv, n = np.unique(acc_levels[np.isfinite(acc_levels)].astype(int), return_counts=True)
        meta["mag_accuracy_counts"] = {str(int(a)): int(b) for a, b in zip(lv, n)}
    if ROTVEC in streams and ACC in streams:
        r, a = streams[ROTVEC], streams[ACC]
        m = streams.get(MAG)
        meta["rotvec_check"] = attitude_checks(r.t_ns, r.values, a.t_ns, a.values,
                                               m.t_ns if m else None, m.values if m else None)
    if ACC in streams and MAG in streams:
        meta["mag_dip_deg"] = magnetic_dip_deg(streams[ACC].t_ns, streams[ACC].values,
                                               streams[MAG].t_ns, streams[MAG].values)

    meta.update({
        "source_format": FORMAT,
        "app": "GetSensorData",
        "time_base": "SensorTimestamp * 1e9 (Android SensorEvent.timestamp, elapsedRealtime clock); AppTimestamp "
                     "records (POSI, GNSS) shifted by app_to_sensor_offset_ns",
        "line_counts": counts,
        "ignored_line_types": {t: n for t, n in counts.items() if t not in RECORDS},
    })
    if unix_offset_ns is not None:
        meta["unix_offset_ns"] = unix_offset_ns
    rec = Recording(streams, device=device, metadata=meta, repairs=repairs, source=source)
    return finish(rec, warn=warn, unix_offset_ns=unix_offset_ns)

