"""Reader for MATLAB Mobile sensor logs saved as a MAT-file: timetables ``Acceleration``, ``AngularVelocity``, ...

Format
======
MATLAB Mobile logs the phone's sensors; saved from MATLAB (``save log.mat``, level 5, ``-v7``) each sensor is a
variable holding a ``timetable`` object:

* ``Acceleration`` (X, Y, Z, m/s^2, gravity included) -> ``acc``;
* ``AngularVelocity`` (X, Y, Z, rad/s) -> ``gyro``;
* ``MagneticField`` (X, Y, Z, microtesla) -> ``mag``;
* ``Position`` (latitude, longitude, altitude, speed, course, hacc) -> ``gps``;
* ``Orientation`` (azimuth, pitch, roll, degrees) is listed in ``metadata["unused_variables"]``, not read.

Device axes: Android's (flat, screen up: ``Acceleration.Z = +9.8``), as the app reports them.

A timetable is a MATLAB class object (MCOS).  The variable holds only a reference (``uint32``: ``0xDD000000``,
the number of dimensions, the dimensions, the object ids, the class id); the objects live in the file's
*subsystem data*, a ``uint8`` variable without a name that is itself a MAT stream (8 bytes of version and
byte order, then elements): a structure whose field ``MCOS`` is an opaque ``FileWrapper__`` object holding a
cell array.  Its first cell is the metadata (``uint32`` words): version, the number of names, 8 segment offsets,
the names (NUL-terminated), then the segments -- 1: classes (4 words each: package name, class name, 0, 0),
2 and 4: property lists (a count, then name, kind, value per property, padded to 8 bytes; kind 1: the value is
the index of a cell, counted from the third; 0: a name; 2: the value itself), 3: objects (6 words each: class,
0, 0, the property list in segment 2, the one in segment 4, a dependency id).  Entry 0 of every segment is a
placeholder; object ids count from 1.  A ``timetable`` saves itself as one property ``any``: a structure with
``data`` (a cell per column), ``varNames`` and ``rowTimes`` (a reference to a ``datetime`` object whose ``data``
is milliseconds since 1970-01-01 UTC, complex when the imaginary part carries sub-millisecond digits).  This
layout is MathWorks' undocumented format, read here as far as these logs need (checked on the eight logs of
GitHub ``Omer1Eryilmaz/SignalProcessing``, MATLAB R2022-23, and on the accelerometer-only logs of
``Tclack88/MatlabSucks`` and ``NIghtwing1914/Assignment2-Ubicomp``); anything else is a :class:`RecordingError`
naming the file.

Times: ``t_ns`` from the whole millisecond of the first event of any sensor (its Unix time in
``metadata["unix_offset_ns"]``).

Streams: ``acc`` (and ``gyro``, ``mag``, ``gps`` where the log has them).
"""

from __future__ import annotations

import warnings

import numpy as np

from core.conventions import ACC, GPS, GYRO, MAG
from core.recording import (
    MAX_BAD_LINES, MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers import matv5
from core.importers._common import acc_csv_recording, finish, gps_values, open_binary, single_csv_files

FORMAT = "matlab-mobile"

#: timetable variable -> (stream, its columns in order)
SENSORS = {
    "Acceleration": (ACC, ("X", "Y", "Z")),
    "AngularVelocity": (GYRO, ("X", "Y", "Z")),
    "MagneticField": (MAG, ("X", "Y", "Z")),
}
POSITION = "Position"
POSITION_COLUMNS = ("latitude", "longitude", "altitude", "speed", "course", "hacc")
#: the variables of a MATLAB Mobile log (any of them, besides ``Acceleration``, marks one)
LOG_VARIABLES = ("Acceleration", "AngularVelocity", "MagneticField", "Orientation", "Position")
#: the first word of an object reference
OBJECT_REF = 0xDD000000


def looks_like(names: list[str]) -> bool:
    """A MAT-file whose variables (:func:`core.importers.matv5.read_mat`'s ``all_names``) are a MATLAB Mobile
    log's: an ``Acceleration`` timetable (alone when only the accelerometer was on, else beside other sensor
    timetables), with the unnamed subsystem data that holds the objects; no other named variable."""
    named = [n for n in names if n]
    return "Acceleration" in named and "" in names and all(n in LOG_VARIABLES for n in named)


class _Objects:
    """The MCOS objects of a MAT-file's subsystem data: each object's class name and properties."""

    def __init__(self, subsystem: np.ndarray, source: str):
        self.source = source
        raw = np.asarray(subsystem, dtype=np.uint8).tobytes()
        if len(raw) < 16 or raw[2:4] not in (b"IM", b"MI"):
            raise self.error("its subsystem data do not start with a version and byte order")
        order = "<" if raw[2:4] == b"IM" else ">"
        values = matv5.values_in(raw, 8, order, source)
        top = values[0] if values else None
        wrapper = top.get("MCOS") if isinstance(top, dict) else None
        if not isinstance(wrapper, matv5.MatOpaque) or not isinstance(wrapper.data, list) or not wrapper.data:
            raise self.error("no MCOS object store in its subsystem data")
        self.cells = wrapper.data
        meta = np.asarray(self.cells[0], dtype=np.uint8).tobytes()
        words = np.frombuffer(meta[:len(meta) - len(meta) % 4], dtype=order + "u4").astype(np.int64)
        if len(words) < 10:
            raise self.error("MCOS metadata too short")
        n_names, offsets = int(words[1]), [int(x) for x in words[2:10]]
        if any(o % 4 or o > len(meta) for o in offsets[:5]) or offsets[:5] != sorted(offsets[:5]):
            raise self.error("MCOS metadata with bad segment offsets")
        self.names = [b.decode("latin-1") for b in meta[40:offsets[0]].split(b"\0")[:n_names]]

        def seg(k: int) -> np.ndarray:
            return words[offsets[k - 1] // 4:offsets[k] // 4]

        classes = seg(1).reshape(-1, 4) if len(seg(1)) % 4 == 0 else self._bad("class table")
        self.class_names = [self._name(int(c[1])) if c[1] else "" for c in classes]  # entry 0: a placeholder
        self.objects = seg(3).reshape(-1, 6) if len(seg(3)) % 6 == 0 else self._bad("object table")
        self.props2, self.props4 = self._prop_lists(seg(2)), self._prop_lists(seg(4))

    def error(self, why: str) -> RecordingError:
        return RecordingError(f"not a MATLAB Mobile log: {why}", self.source)

    def _bad(self, what: str):
        raise self.error(f"MCOS metadata: a {what} of the wrong length")

    def _name(self, i: int) -> str:
        if not 1 <= i <= len(self.names):
            raise self.error(f"MCOS metadata: name {i} of {len(self.names)}")
        return self.names[i - 1]

    def _prop_lists(self, w: np.ndarray) -> list[list[tuple[int, int, int]]]:
        out, pos = [], 0
        while pos < len(w):
            n = int(w[pos])
            if n < 0 or pos + 1 + 3 * n > len(w):
                raise self.error("MCOS metadata: a property list runs past its segment")
            out.append([tuple(int(x) for x in w[pos + 1 + 3 * k:pos + 4 + 3 * k]) for k in range(n)])
            pos += 1 + 3 * n
            pos += pos % 2  # padded to 8 bytes
        return out

    def _value(self, kind: int, value: int):
        if kind == 1:
            if not 0 <= value + 2 < len(self.cells):
                raise self.error(f"MCOS property in cell {value + 2} of {len(self.cells)}")
            return self.cells[value + 2]
        return self._name(value) if kind == 0 else value

    def get(self, obj_id: int) -> tuple[str, dict]:
        """Object ``obj_id`` (from 1): its class name and properties (name -> value)."""
        if not 1 <= obj_id < len(self.objects):
            raise self.error(f"object {obj_id} of {len(self.objects) - 1}")
        cls, _, _, i2, i4, _ = (int(x) for x in self.objects[obj_id])
        if not 0 <= cls < len(self.class_names) or not 0 <= i2 < len(self.props2) or not 0 <= i4 < len(self.props4):
            raise self.error(f"object {obj_id}: bad class or property list")
        props = {self._name(n): self._value(k, v) for n, k, v in self.props2[i2] + self.props4[i4]}
        return self.class_names[cls], props

    def ref(self, value, want: str) -> dict:
        """The properties of the one object of class ``want`` that a reference array (or opaque) points to."""
        if isinstance(value, matv5.MatOpaque):
            value = value.data
        a = np.asarray(value).ravel().astype(np.int64) if value is not None else np.zeros(0, np.int64)
        if len(a) < 4 or a[0] != OBJECT_REF:
            raise self.error(f"a {want} that is not an object reference")
        nd = int(a[1])
        count = int(np.prod(a[2:2 + nd]))
        if count != 1 or len(a) < 2 + nd + 2:
            raise self.error(f"a reference to {count} objects where one {want} was expected")
        cls, props = self.get(int(a[2 + nd]))
        if cls != want:
            raise self.error(f"a {cls} where a {want} was expected")
        return props


def _timetable(objs: _Objects, ref, name: str, columns: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``(unix_ms, values (n, len(columns)))`` of the timetable variable ``name``; ``unix_ms`` complex: the
    sub-millisecond digits in the imaginary part (as MATLAB's datetime keeps them)."""
    saved = objs.ref(ref, "timetable").get("any")
    if not isinstance(saved, dict) or not {"data", "varNames", "rowTimes"} <= set(saved):
        raise objs.error(f"timetable {name} without data, varNames and rowTimes")
    var_names = [str(v) for v in saved["varNames"]]
    missing = [c for c in columns if c not in var_names]
    if missing:
        raise objs.error(f"timetable {name} lacks column(s) {', '.join(missing)} (has {', '.join(var_names)})")
    cols = [np.asarray(saved["data"][var_names.index(c)], dtype=np.float64).ravel() for c in columns]
    times = objs.ref(saved["rowTimes"], "datetime").get("data")
    ms = np.asarray(times).ravel().astype(np.complex128)
    if any(len(c) != len(ms) for c in cols):
        raise objs.error(f"timetable {name}: {len(ms)} times but columns of {[len(c) for c in cols]} values")
    return ms, np.column_stack(cols) if cols else np.zeros((len(ms), 0))


def read_matlabmobile(path: str, *, warn: bool = True,
                      max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a MATLAB Mobile log MAT-file (plain or gzip) into a :class:`Recording` (see the module doc)."""
    path = str(path)
    with open_binary(path) as f:
        mat = matv5.read_mat(f, path, max_uncompressed_bytes=max_uncompressed_bytes, objects=True)
    if not looks_like(mat.all_names):
        raise RecordingError("not a MATLAB Mobile log: no Acceleration timetable with the subsystem data, or a "
                             "variable a MATLAB Mobile log does not have", path)
    objs = _Objects(mat[""], path)
    raw: dict = {}
    for var, (stream, columns) in SENSORS.items():
        if var in mat.variables:
            raw[stream] = _timetable(objs, mat[var], var, columns)
    if POSITION in mat.variables:
        raw[GPS] = _timetable(objs, mat[POSITION], POSITION, POSITION_COLUMNS)
    starts = [ms.real.min() for ms, _ in raw.values() if len(ms)]
    if not starts or not np.isfinite(min(starts)):
        raise RecordingError("MATLAB Mobile log without sensor samples (or with times that are not numbers)", path)
    t0_ms = float(np.floor(min(starts)))  # whole ms: exact in float64, so the offsets below keep their ns
    t0_ns = int(t0_ms) * 1_000_000
    streams = {}
    for stream, (ms, v) in raw.items():
        t_ns = np.round(((ms.real - t0_ms) + ms.imag) * 1e6).astype(np.int64)
        if stream == GPS:
            lat, lon, alt, speed, course, hacc = v.T
            v = gps_values(lat, lon, alt, hacc, speed, course)
        streams[stream] = make_stream(stream, t_ns, v)
    meta = {
        "source_format": FORMAT,
        "app": "MATLAB Mobile (sensor log saved as a MAT-file)",
        "time_base": "t_ns = the timetables' datetime (Unix ms) * 1e6 - unix_offset_ns (the whole millisecond of the "
                     "first event of any sensor)",
        "unix_offset_ns": t0_ns,
        "unused_variables": [n for n in mat.all_names if n and n not in SENSORS and n != POSITION],
    }
    rec = Recording(streams, metadata=meta, repairs=[], source=path)
    rec.device = {"app": "MATLAB Mobile"}
    if warn:
        for r in rec.repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=2)
    return finish(rec, warn=warn, unix_offset_ns=t0_ns)


# ---------------------------------------------------------------------------
# the CSV MATLAB writes from such a log's accelerometer timetable

#: the header ``writetable(splitvars(struct2table(load(log))))`` writes for an accelerometer-only log
CSV_HEADER = ["Acceleration_Timestamp", "X", "Y", "Z"]
CSV_FORMAT = "matlab-mobile-csv"
CSV_WHAT = "MATLAB Mobile accelerometer CSV (Acceleration_Timestamp,X,Y,Z)"
_MONTHS = {m: i + 1 for i, m in enumerate(("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct",
                                           "Nov", "Dec"))}


def looks_like_csv(head: str) -> bool:
    """The first line is the header ``Acceleration_Timestamp,X,Y,Z`` (quotes and spaces around names allowed)."""
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip()
    return [n.strip().strip('"').strip() for n in first.split(",")] == CSV_HEADER


def csv_files(fs) -> list[str]:
    """The CSVs of this layout in a folder or zip (top level and one folder down)."""
    return single_csv_files(fs, looks_like_csv)


def _datetime_ms(s: str) -> float:
    """MATLAB's default datetime text ``16-Mar-2023 13:51:57.940`` (local time, no zone) -> ms since 1970 as if UTC."""
    day, clock = s.strip().strip('"').split(" ")
    d, mon, y = day.split("-")
    h, mi, sec = clock.split(":")
    days = (np.datetime64(f"{int(y):04d}-{_MONTHS[mon]:02d}-{int(d):02d}") - np.datetime64("1970-01-01")).astype(int)
    return ((int(days) * 24 + int(h)) * 60 + int(mi)) * 60_000.0 + float(sec) * 1000.0


def _read_csv_values(text, where: str, repairs: list[str]) -> np.ndarray:
    out, bad, n = [], [], 0
    header_seen = False
    for first_no, lines in text:
        for k, ln in enumerate(lines):
            if not header_seen:
                header_seen = True
                continue
            if not ln.strip():
                continue
            n += 1
            f = ln.split(",")
            try:
                if len(f) < 4:
                    raise ValueError("missing fields")
                out.append((_datetime_ms(f[0]), float(f[1]), float(f[2]), float(f[3])))
            except (ValueError, KeyError) as e:
                bad.append(RecordingError(f"not a time and three numbers ({e})", where, first_no + k))
                if len(bad) > MAX_BAD_LINES:
                    break
    if text.tail.strip():
        repairs.append(f"{where}: dropped an incomplete last line {text.tail_line} (no newline: the file was cut "
                       "off mid-write)")
    skip_bad_lines(bad, n, where, repairs)
    return np.array(out, dtype=np.float64).reshape(-1, 4)


def read_matlabmobile_csv(path: str, *, warn: bool = True,
                          max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read the ``Acceleration_Timestamp,X,Y,Z`` CSV MATLAB writes from a MATLAB Mobile accelerometer log.

    ``Acceleration_Timestamp`` is MATLAB's datetime text (``16-Mar-2023 13:51:57.940``: local time, zone not
    written, milliseconds); ``t_ns`` counts from the first line's.  ``X, Y, Z``: m/s^2 with gravity, Android axes
    (the median ``|a|`` is checked, :func:`core.importers._common.acceleration_in_m_s2`).  Checked on the CSVs of
    GitHub ``Tclack88/MatlabSucks`` (``sensor_systems/pedometer``, 53 Hz, the same samples as its MAT-files).
    Streams: ``acc``.
    """
    meta = {
        "source_format": CSV_FORMAT,
        "app": "MATLAB Mobile (its accelerometer timetable written to CSV by MATLAB)",
        "time_base": "t_ns = Acceleration_Timestamp (local datetime text, ms) - the first line's; absolute time "
                     "unknown (no time zone in the file)",
    }
    return acc_csv_recording(path, looks_like_csv, _read_csv_values, CSV_WHAT, meta, warn=warn,
                             max_uncompressed_bytes=max_uncompressed_bytes, from_first=True)
