"""Reader for Microsoft / XYZ10 Indoor Location Competition 2.0 traces ("path data" files).

The format of the 2020 competition's sample data and of its Kaggle edition
("Indoor Location & Navigation"): one trace per walk, written by the
collectors' Android app.

Format
======
Plain text (here also gzip), tab-separated.  ``#`` lines are the header::

    #	startTime:1574142011992
    #	SiteID:5dbc1d84c1eb61796cf7c010	SiteName:...	FloorId:...	FloorName:F3
    #	Brand:OPPO	Model:PBCM10	AndroidName:8.1.0	APILevel:27
    #	type:1	name:BMI160 Accelerometer	version:...	vendor:BOSCH	resolution:...	power:...	maximumRange:...
    #	VersionName:v20191105-nightly-16-gcd7805b	VersionCode:403
    ...
    #	endTime:1574142039898

then one record per line, ``unix_ms <TAB> TYPE <TAB> values...``.  The
records read here::

    unix_ms  TYPE_ACCELEROMETER                x  y  z  accuracy     m/s^2, gravity included
    unix_ms  TYPE_GYROSCOPE                    x  y  z  accuracy     rad/s
    unix_ms  TYPE_MAGNETIC_FIELD               x  y  z  accuracy     uT (the OS-calibrated field)
    unix_ms  TYPE_ROTATION_VECTOR              x  y  z  accuracy     Android's rotation vector
    unix_ms  TYPE_GYROSCOPE_UNCALIBRATED       x y z  bx by bz  accuracy   rad/s, and the bias estimate
    unix_ms  TYPE_MAGNETIC_FIELD_UNCALIBRATED  x y z  bx by bz  accuracy   uT, and the hard-iron estimate
    unix_ms  TYPE_WAYPOINT                     x  y                  the surveyor's ground truth (m)

Every other record type (``TYPE_WIFI``, ``TYPE_BEACON``,
``TYPE_ACCELEROMETER_UNCALIBRATED``, ...) is counted in
``metadata["ignored_line_types"]``, not read.  The accuracy field may be
absent; fewer fields than the values, more than the values and the
accuracy, or a field that is not a number, is a bad line: skipped and
counted, or, past 100 or 1 % of the lines, a :class:`RecordingError`
naming the first.  The competition's README warns that a line may miss
its newline, which glues two records into one line: such a line (a second
``TYPE_`` field) is dropped and counted apart, in ``repairs``, as a known
defect of the writer rather than damage (neither record can be told apart
reliably: the accuracy of the first and the time of the second run
together).

Time base
=========
The app converted ``SensorEvent.timestamp`` to Unix milliseconds, so every
record -- waypoints included -- is on one clock, with 1 ms resolution:
``t_ns = unix_ms * 1_000_000`` (``t_ns`` *is* Unix time;
``metadata["unix_offset_ns"]`` is 0).

Units, axes and attitude
========================
Android ``SensorEvent.values`` in the Android device frame: copied as they
are.  ``TYPE_ROTATION_VECTOR`` is ``values[0..2]`` of Android's rotation
vector, the vector part of the unit quaternion rotating device vectors into
East-North-Up (y to magnetic north); the scalar part is restored as
``w = sqrt(max(0, 1 - x^2 - y^2 - z^2))`` (Android's
``getQuaternionFromVector``): the ``rotvec`` stream ``(w, x, y, z)``.  The
uncalibrated gyroscope and magnetometer become ``gyro_uncal`` and
``mag_uncal`` (their first three values; the OS's bias and hard-iron
estimates are not kept).

Ground truth
============
``TYPE_WAYPOINT x y`` is the position the surveyor marked, in metres in the
floor map's frame: the ``waypoint`` stream (``east_m``, ``north_m``).  On
the competition's maps x is East and y North from the south-west corner of
the floor's GeoJSON bounding box (the map's ``floor_info.json`` width and
height are that box's extent in metres; checked on site2/F3), so the
waypoints share the East-North axes of :mod:`core`, not its origin.

Streams: ``acc``, ``gyro``, ``mag``, ``rotvec``, ``gyro_uncal``,
``mag_uncal`` and ``waypoint``, each only when the file has such records.
``device``: platform, brand, model, os_version, android_api from the
header; ``metadata["site"]`` the site and floor ids and names,
``metadata["trace_header"]`` the header's other fields as written and
``metadata["sensors"]`` its sensor lines.
"""

from __future__ import annotations

import re
import warnings

import numpy as np

from core.conventions import ACC, GYRO, MAG, ROTVEC
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import (
    EXTRA_STREAM_SPECS, GYRO_UNCAL, MAG_UNCAL, WAYPOINT, feed_lines, finish, open_text,
)
from core.importers._csv import ColumnBuffer, fixed_rows

FORMAT = "msindoor"

#: record type -> (stream, number of values read)
RECORDS: dict[str, tuple[str, int]] = {
    "TYPE_ACCELEROMETER": (ACC, 3),
    "TYPE_GYROSCOPE": (GYRO, 3),
    "TYPE_MAGNETIC_FIELD": (MAG, 3),
    "TYPE_ROTATION_VECTOR": (ROTVEC, 3),
    "TYPE_GYROSCOPE_UNCALIBRATED": (GYRO_UNCAL, 6),
    "TYPE_MAGNETIC_FIELD_UNCALIBRATED": (MAG_UNCAL, 6),
    "TYPE_WAYPOINT": (WAYPOINT, 2),
}

#: the fields of a record with 2, 3 or 6 values (for messages)
_FIELDS = {2: ["unix_ms", "type", "x", "y"], 3: ["unix_ms", "type", "x", "y", "z", "accuracy"],
           6: ["unix_ms", "type", "x", "y", "z", "bias_x", "bias_y", "bias_z", "accuracy"]}

#: largest |unix_ms| whose nanoseconds fit int64 with room to spare
_MAX_MS = 9_000_000_000_000

_RECORD_RE = re.compile(r"^\d{9,16}\tTYPE_[A-Z0-9_]+\t", re.M)
_HEADER_RE = re.compile(r"^#\t(startTime|SiteID|Brand):", re.M)

#: distinct record types counted in ``metadata["line_counts"]``; more are counted as "(other)"
MAX_LINE_TYPES = 1000
#: header lines kept
MAX_COMMENTS = 1000


def looks_like(head: str) -> bool:
    """True if the start of a text file looks like a trace (its header, or three record lines)."""
    if head.lstrip().startswith("#") and _HEADER_RE.search(head[:8192]):
        return True
    return len(_RECORD_RE.findall(head)) >= 3


def read_msindoor(path: str, *, warn: bool = True, max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES,
                  streams: tuple[str, ...] | None = None) -> Recording:
    """Read a trace (plain or gzip) into a :class:`Recording` (see the module doc).

    The file is streamed a chunk of lines at a time; a gzip stream
    inflating to over ``max_uncompressed_bytes`` is refused while it is read.
    ``streams``: read only these (e.g. ``("waypoint",)``, a quick look at the
    ground truth); lines of other records are then neither parsed nor counted,
    and a trace without such records gives a recording without streams.
    """
    path = str(path)
    repairs: list[str] = []
    with open_text(path, repairs, max_uncompressed_bytes) as text, np.errstate(all="ignore"):
        return _parse(text, path, warn, repairs, streams)


def _header(comments: list[str]) -> tuple[dict, list[dict]]:
    fields: dict[str, str] = {}
    sensors: list[dict] = []
    for line in comments:
        row = {}
        for field in line[1:].strip().split("\t"):
            k, _, v = field.partition(":")
            if v:
                row[k.strip()] = v.strip()
        if "type" in row and "name" in row:
            sensors.append(row)
        else:
            fields.update(row)
    return fields, sensors


def _parse(text, source: str, warn: bool, repairs: list[str], only: tuple[str, ...] | None = None) -> Recording:
    markers = None if only is None else [f"\t{tag}\t" for tag, (name, _) in RECORDS.items() if name in only]
    comments: list[str] = []
    counts: dict[str, int] = {}
    t_buf = {tag: ColumnBuffer(1, np.int64) for tag in RECORDS}
    v_buf = {tag: ColumnBuffer(k) for tag, (_, k) in RECORDS.items()}
    bad: list[RecordingError] = []
    glued: list[int] = []

    def chunk(first: int, lines: list[str]) -> None:
        rows: dict[str, tuple[list[str], list[int]]] = {}
        numbered = enumerate(lines) if markers is None else \
            [(i, ln) for i, ln in enumerate(lines) if ln[:1] == "#" or any(m in ln for m in markers)]
        for i, line in numbered:
            if not line or line[0] == "#":
                if line and len(comments) < MAX_COMMENTS:
                    comments.append(line)
                continue
            tag = line.partition("\t")[2].partition("\t")[0].strip()[:64] or "(no type)"
            if line.count("\tTYPE_") > 1:
                glued.append(first + i)
                continue
            if tag not in counts and len(counts) >= MAX_LINE_TYPES and tag not in RECORDS:
                tag = "(other)"
            counts[tag] = counts.get(tag, 0) + 1
            if tag in RECORDS:
                r = rows.setdefault(tag, ([], []))
                r[0].append(line)
                r[1].append(first + i)
        for tag, (rs, nos) in rows.items():
            k = RECORDS[tag][1]
            nmax = 2 + k + (tag != "TYPE_WAYPOINT")  # time, type, the values and (sensors) the accuracy
            ints, vals, kept, errs = fixed_rows(rs, [0] + list(range(2, 2 + k)), "\t", (2 + k, nmax),
                                                names=_FIELDS[k])
            bad.extend(RecordingError(f"{tag}: {msg}", source, nos[j]) for j, msg in errs)
            far = np.abs(ints) > _MAX_MS
            if far.any():
                j = int(np.flatnonzero(kept)[np.flatnonzero(far)[0]])
                bad.append(RecordingError(f"{tag}: the time {int(ints[far][0])} ms is out of range", source, nos[j]))
                ints, vals = ints[~far], vals[~far]
            t_buf[tag].append(ints[:, None])
            v_buf[tag].append(vals)

    def tail(lineno: int, last: str) -> None:
        if last[0] != "#" and "\tTYPE_" in last:
            repairs.append(f"{source}: dropped an incomplete last line {lineno} (no newline: the trace was cut off "
                           "mid-write; its last number may be cut short)")
        else:
            chunk(lineno, [last])

    feed_lines(text, source, repairs, chunk, bad, tail)
    bad.sort(key=lambda e: e.line or 0)
    skip_bad_lines(bad, sum(counts.values()), source, repairs)
    if glued:
        repairs.append(f"{source}: skipped {len(glued)} malformed line(s) holding two records (a missing newline, "
                       f"a known defect of these traces; first: line {glued[0]})")
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=3)

    streams = {}
    for tag, (name, _) in RECORDS.items():
        if not len(t_buf[tag]):
            continue
        t_ns = t_buf[tag].array()[:, 0] * 1_000_000
        v = v_buf[tag].array()
        if name == ROTVEC:
            x, y, z = v[:, 0], v[:, 1], v[:, 2]
            w = np.sqrt(np.maximum(0.0, 1.0 - (x * x + y * y + z * z)))
            streams[name] = make_stream(name, t_ns, np.column_stack([w, x, y, z]),
                                        note="Android rotation vector (TYPE_ROTATION_VECTOR) as an ENU<-device "
                                             "quaternion (w, x, y, z); heading relative to magnetic north")
        elif name in (ACC, GYRO, MAG):
            streams[name] = make_stream(name, t_ns, v)
        else:
            spec = EXTRA_STREAM_SPECS[name]
            streams[name] = make_stream(name, t_ns, v[:, :len(spec["columns"])], spec["columns"], spec["unit"],
                                        spec["note"])
    if only is None and not any(n in streams for n in (ACC, GYRO, MAG, ROTVEC)):
        raise RecordingError("no TYPE_ACCELEROMETER, TYPE_GYROSCOPE, TYPE_MAGNETIC_FIELD or TYPE_ROTATION_VECTOR "
                             "records: not an indoor-location trace, or an empty one", source)

    fields, sensors = _header(comments)
    device: dict = {"platform": "android"}
    for key, name in (("Brand", "brand"), ("Model", "model"), ("AndroidName", "os_version")):
        if fields.get(key):
            device[name] = fields[key]
    if fields.get("APILevel", "").isdigit():
        device["android_api"] = int(fields["APILevel"])
    meta = {
        "source_format": FORMAT,
        "app": "XYZ10 indoor-location collector",
        "app_version": fields.get("VersionName", ""),
        "time_base": "t_ns = unix_ms * 1e6: the app logged SensorEvent.timestamp as Unix milliseconds (t_ns is "
                     "Unix time)",
        "unix_offset_ns": 0,
        "unix_time_source": "the records' Unix-millisecond times",
        "site": {k: fields[h] for k, h in (("site_id", "SiteID"), ("site_name", "SiteName"),
                                           ("floor_id", "FloorId"), ("floor_name", "FloorName")) if h in fields},
        "waypoint_frame": "floor map metres: x East, y North from the south-west corner of the floor's map",
        "trace_header": fields,
        "sensors": sensors,
        "line_counts": dict(sorted(counts.items())),
        "ignored_line_types": {t: n for t, n in sorted(counts.items()) if t not in RECORDS},
    }
    rec = Recording(streams, device=device, metadata=meta, repairs=repairs, source=source)
    if only is not None and not streams:
        return rec  # none of the records asked for: an empty answer, not an error
    return finish(rec, warn=warn, unix_offset_ns=0)
