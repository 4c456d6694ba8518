"""Reader for x-io Technologies IMU logs: NGIMU ``sensors.csv`` (a file or its session folder) and x-IMU CSVs.

Format
======
Comma-separated text (here also gzip) with a header line of
``<Sensor> <Axis> (<unit>)`` names::

    Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),...   (NGIMU)
    Packet number,Gyroscope X (deg/s),...,Accelerometer Z (g),Magnetometer X (G),...               (x-IMU)

* NGIMU: the first column ``Time (s)`` is the device's time in seconds:
  ``t_ns = round(time * 1e9)``.  A session folder (or zip) of an NGIMU
  SD-card log is read through its ``sensors.csv``.  The NGIMU repeats a
  row now and then (same time, same values): the recording repair keeps
  the first (:func:`core.recording.repair_recording`, with its warning).
* x-IMU (``*_CalInertialAndMag.csv``, the calibrated export of the x-IMU
  GUI): the first column is the packet number, which skips (packets of other
  kinds share the counter), so it is no clock: row ``i`` of the file is at
  ``i / rate`` with the rate the x-IMU was set to (``ximu_rate_hz``, default
  :data:`XIMU_RATE_HZ`, the rate of x-io's own gait-tracking examples;
  the file does not say it).  ``metadata["rate_hz_assumed"]`` records it.

Columns found by name; gyroscope and accelerometer X/Y/Z are required, the
magnetometer and the NGIMU barometer are read when present.  Units as
x-io writes them, converted to :mod:`core`'s: ``deg/s`` -> rad/s, ``g``
-> m/s^2 (x 9.80665), ``uT`` (or ``µT``) kept, ``G`` (gauss) -> uT (x 100),
``hPa`` kept (``pressure`` stream); any other unit is a
:class:`RecordingError` naming it.  Axes: the sensor's own (x-io's board
axes), not the Android device axes.  Absolute time unknown.  The files
do not say where the IMU was worn: ``device["placement"]`` is left out
(``pdr replay`` detects foot mounting from the signals).

A line with a field that is not a number or with too few fields is a bad
line: skipped and counted, or, past 100 or 1 % of the lines, a
:class:`RecordingError` naming the first.
"""

from __future__ import annotations

import os
import re
import warnings

import numpy as np

from core.conventions import ACC, GYRO, MAG, STANDARD_GRAVITY_M_S2
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import EXTRA_STREAM_SPECS, PRESSURE, FileSet, finish, first_bad_time, head_lines, \
    is_zip, open_text
from core.importers._csv import Table

FORMAT = "x-io"

#: the x-IMU's sample rate assumed for row times (Hz): x-io's gait-tracking examples log at 256 Hz
XIMU_RATE_HZ = 256.0
NGIMU_TIME = "Time (s)"
XIMU_COUNTER = "Packet number"
SESSION_FILE = "sensors.csv"

_COLUMN = re.compile(r"^(Gyroscope|Accelerometer|Magnetometer) ([XYZ]) \(([^)]*)\)$")
#: sensor -> (stream, unit -> factor to core's unit)
SENSORS = {
    "Gyroscope": (GYRO, {"deg/s": np.pi / 180.0, "rad/s": 1.0}),
    "Accelerometer": (ACC, {"g": STANDARD_GRAVITY_M_S2, "m/s^2": 1.0, "m/s/s": 1.0}),
    "Magnetometer": (MAG, {"uT": 1.0, "µT": 1.0, "G": 100.0, "Gauss": 100.0, "mG": 0.1}),
}
BAROMETER = "Barometer (hPa)"


def _header(line: str) -> list[str]:
    return [h.strip().strip('"').strip() for h in line.lstrip("\ufeff").split(",")]


def looks_like_csv(head: str) -> bool:
    """An x-io CSV: the header starts with ``Time (s)`` or ``Packet number`` and names the gyroscope and
    accelerometer X/Y/Z columns as ``Gyroscope X (deg/s)``, ``Accelerometer X (g)``, ..."""
    lines = head_lines(head, 2)
    if not lines:
        return False
    names = _header(lines[0])
    if not names or names[0] not in (NGIMU_TIME, XIMU_COUNTER):
        return False
    found = {(m.group(1), m.group(2)) for m in map(_COLUMN.match, names) if m}
    return all((s, a) in found for s in ("Gyroscope", "Accelerometer") for a in "XYZ")


def _session_file(fs: FileSet) -> str | None:
    for n in fs.names():
        if n.split("/")[-1].lower() == SESSION_FILE and n.count("/") <= 1:
            return n
    return None


def looks_like_folder(fs: FileSet) -> bool:
    """True if a folder (or zip) is an NGIMU session: a ``sensors.csv`` of this format."""
    n = _session_file(fs)
    return n is not None and looks_like_csv(fs.head(n))


def read_xio(path: str, *, warn: bool = True, ximu_rate_hz: float = XIMU_RATE_HZ,
             max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read an x-io CSV (NGIMU ``sensors.csv`` or its session folder/zip, or an x-IMU CSV) (see the module doc).

    The file is streamed a chunk of lines at a time; a gzip stream (or zip
    member) inflating to over ``max_uncompressed_bytes`` is refused while it
    is read.
    """
    path = str(path)
    if not os.path.exists(path):
        raise RecordingError("cannot open: no such file or folder", path)
    if not (ximu_rate_hz > 0 and np.isfinite(ximu_rate_hz)):
        raise ValueError(f"ximu_rate_hz must be a positive number, not {ximu_rate_hz!r}")
    repairs: list[str] = []
    with np.errstate(all="ignore"):
        if os.path.isdir(path) or is_zip(path):
            with FileSet(path, max_uncompressed_bytes) as fs:
                name = _session_file(fs)
                if name is None:
                    raise RecordingError(f"no NGIMU {SESSION_FILE} in this folder or archive", path)
                with fs.text(name) as text:
                    rec = _parse(text, fs.where(name), repairs, ximu_rate_hz)
                repairs += fs.repairs
        else:
            with open_text(path, repairs, max_uncompressed_bytes) as text:
                rec = _parse(text, path, repairs, ximu_rate_hz)
    rec.source = path
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=2)
    return finish(rec, warn=warn)


def _parse(text, source: str, repairs: list[str], rate_hz: float) -> Recording:
    table = Table(text, source, ",")
    if table.blank:
        raise RecordingError("empty file", source)
    first = table.header[0] if table.header else ""
    if first not in (NGIMU_TIME, XIMU_COUNTER):
        raise RecordingError(f"x-io CSV: the first column is {first[:60]!r}, not {NGIMU_TIME!r} (NGIMU) or "
                             f"{XIMU_COUNTER!r} (x-IMU)", source, 1)
    ngimu = first == NGIMU_TIME
    groups: dict[str, tuple[list[int], float, str]] = {}
    for sensor, (stream, units) in SENSORS.items():
        cols, unit = [], None
        for axis in "XYZ":
            hit = [(i, m.group(3)) for i, m in enumerate(map(_COLUMN.match, table.header))
                   if m and m.group(1) == sensor and m.group(2) == axis]
            if hit:
                cols.append(hit[0][0])
                unit = hit[0][1]
        if not cols:
            continue
        if len(cols) != 3:
            raise RecordingError(f"x-io CSV: {sensor} has {len(cols)} of its X/Y/Z columns", source, 1)
        if unit not in units:
            raise RecordingError(f"x-io CSV: {sensor} in {unit!r}, not one of {', '.join(units)}", source, 1)
        groups[stream] = (cols, units[unit], unit)
    for need in (GYRO, ACC):
        if need not in groups:
            raise RecordingError(f"x-io CSV: no {'gyroscope' if need == GYRO else 'accelerometer'} X/Y/Z columns "
                                 f"(header: {','.join(table.header)[:300]})", source, 1)
    baro = table.index(BAROMETER)
    spec = [(0, "f")] + [(c, "f") for s in groups.values() for c in s[0]]
    if baro is not None:
        spec.append((baro, "f"))
    data = table.read(spec, with_lines=True)
    skip_bad_lines(table.bad, table.n_lines, source, repairs)
    if table.dropped_tail is not None:
        repairs.append(f"{source}: dropped an incomplete last line {table.dropped_tail} (no newline: the log was "
                       "cut off mid-write)")
    v = data["v"]
    if not len(v):
        raise RecordingError("no data lines", source)
    if ngimu:
        j = first_bad_time(v[:, 0])
        if j is not None:
            raise RecordingError(f"'{NGIMU_TIME}' is not a usable time: {float(v[j, 0])!r}", source,
                                 int(data["line"][j]))
        t_ns = np.round(v[:, 0] * 1e9).astype(np.int64)
        time_base = "t_ns = round(Time (s) * 1e9): the NGIMU's clock; absolute time unknown"
    else:
        t_ns = np.round(np.arange(len(v)) * (1e9 / rate_hz)).astype(np.int64)
        time_base = (f"t_ns = row index / {rate_hz:g} Hz (the x-IMU's set rate, assumed: packet numbers skip and "
                     "are no clock); absolute time unknown")
    streams = {}
    k = 1
    for stream, (cols, factor, unit) in groups.items():
        x = v[:, k:k + 3]
        if stream == GYRO:
            x = np.radians(x) if unit == "deg/s" else x * factor
        elif factor != 1.0:
            x = x * factor
        streams[stream] = make_stream(stream, t_ns, x, note=f"x-io {stream} from {unit}, sensor axes")
        k += 3
    if baro is not None:
        ps = EXTRA_STREAM_SPECS[PRESSURE]
        streams[PRESSURE] = make_stream(PRESSURE, t_ns, v[:, k:k + 1], ps["columns"], ps["unit"], ps["note"])
    device = {"model": "x-io NGIMU" if ngimu else "x-io x-IMU", "axes": "sensor axes"}
    meta: dict = {"source_format": FORMAT, "app": device["model"], "layout": "ngimu" if ngimu else "x-imu",
                  "time_base": time_base}
    if not ngimu:
        meta["rate_hz_assumed"] = float(rate_hz)
    return Recording(streams, device=device, metadata=meta, repairs=repairs, source=source)
