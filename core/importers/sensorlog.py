"""Reader for a SensorLog CSV (the iOS app by Bernd Thomas): ``accelerometerTimestamp_sinceReboot``,
``accelerometerAccelerationX`` ... columns.

Format
======
Text (here also gzip), ``,``-separated, one header line naming the columns, then one row per logged sample.  A
column name may carry its unit in brackets (``accelerometerAccelerationX(G)``, newer app versions) or not
(``accelerometerAccelerationX``, the 2016 files this reader was checked on); other columns (a converter's
``time(ms)``, the location, heading, attitude, altimeter columns) may come before, between or after and are not
read.  Each row repeats the latest value of every sensor; a sensor's sample is a row whose own timestamp is newer
than the previous one (rows repeating it are not samples and are dropped, counted in
``metadata["repeated_rows"]``).

* ``accelerometerTimestamp_sinceReboot`` (s since the phone booted), ``accelerometerAccelerationX/Y/Z``: Core
  Motion's raw accelerometer **in g, with iOS's sign** (flat, screen up: ``Z = -1``).  ``acc = -9.80665 * a``
  (Android axes: flat, screen up ``+9.8``), ``t_ns = timestamp * 1e9``.  The median magnitude must be about 1 g
  (:func:`core.importers._common.acceleration_in_m_s2` on the converted values; anything else is refused).
* ``gyroTimestamp_sinceReboot``, ``gyroRotationX/Y/Z``: the raw gyroscope in rad/s (right-handed, as Android's:
  kept as is), when present.
* ``motionTimestamp_sinceReboot``, ``motionMagneticFieldX/Y/Z``: Core Motion's calibrated magnetic field in uT,
  when present and not all zero.

All three timestamps are the same clock (since reboot): absolute time is unknown (the location columns are not
read: they repeat the last fix on every row).  A row with a field that is not a number, or fewer fields than the
columns read, is a bad line: skipped and counted, or, past 100 or 1 % of the lines, a :class:`RecordingError`
naming the first.  Checked on the SensorLog walks of GitHub ``zDrakon/SensorDataExplorer``
(``data/Shivani/*50StepWalk*.csv``: iPhone 6 Plus, 103 Hz, median ``|a|`` 1.01 g).

Streams: ``acc``, ``gyro`` and ``mag`` where present.
"""

from __future__ import annotations

import re
import warnings

import numpy as np

from core.conventions import ACC, GYRO, MAG, STANDARD_GRAVITY_M_S2
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import FileSet, acceleration_in_m_s2, finish, read_single_csv, single_csv_files
from core.importers._csv import Table

FORMAT = "sensorlog"
WHAT = "SensorLog CSV (accelerometerTimestamp_sinceReboot, accelerometerAccelerationX, ...)"

#: stream -> (its timestamp column, its three value columns), names without a unit suffix
SENSORS = {
    ACC: ("accelerometerTimestamp_sinceReboot",
          ("accelerometerAccelerationX", "accelerometerAccelerationY", "accelerometerAccelerationZ")),
    GYRO: ("gyroTimestamp_sinceReboot", ("gyroRotationX", "gyroRotationY", "gyroRotationZ")),
    MAG: ("motionTimestamp_sinceReboot", ("motionMagneticFieldX", "motionMagneticFieldY", "motionMagneticFieldZ")),
}
_UNIT = re.compile(r"\s*\([^)]*\)\s*$")


def _bare(name: str) -> str:
    """A column name without its unit suffix (``accelerometerAccelerationX(G)`` -> ``accelerometerAccelerationX``)."""
    return _UNIT.sub("", name.strip().strip('"').strip()).lower()


def looks_like_csv(head: str) -> bool:
    """The first line names SensorLog's accelerometer columns (with or without units)."""
    first = head.lstrip("\ufeff").replace("\r", "\n").split("\n", 1)[0]
    names = {_bare(n) for n in first.split(",")}
    t, cols = SENSORS[ACC]
    return t.lower() in names and all(c.lower() in names for c in cols)


def csv_files(fs: FileSet) -> list[str]:
    """The SensorLog CSVs in a folder or zip (top level and one folder down)."""
    return single_csv_files(fs, looks_like_csv)


def read_sensorlog(path: str, *, warn: bool = True,
                   max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a SensorLog CSV (plain or gzip, or the one such CSV of a folder or zip)."""
    path = str(path)
    repairs: list[str] = []
    notes: dict = {}
    blocks = read_single_csv(path, looks_like_csv, _read_values, WHAT, repairs, max_uncompressed_bytes)
    streams, repeated = {}, {}
    for name, v in blocks.items():
        new = np.ones(len(v), dtype=bool)
        new[1:] = np.diff(v[:, 0]) > 0  # a row repeating the sensor's last timestamp is not a sample
        repeated[name] = int((~new).sum())
        v = v[new]
        if name == MAG and (not len(v) or not np.any(v[:, 1:])):
            continue  # no magnetometer logged
        vals = v[:, 1:4]
        if name == ACC:
            vals = acceleration_in_m_s2(-STANDARD_GRAVITY_M_S2 * vals, "accelerometerAcceleration", path, repairs, notes)
        streams[name] = make_stream(name, np.round(v[:, 0] * 1e9).astype(np.int64), vals)
    if not len(streams.get(ACC, ())):
        raise RecordingError("no accelerometer rows", path)
    meta = {
        "source_format": FORMAT,
        "app": "SensorLog (iOS)",
        "time_base": "t_ns = the sensors' timestamp_sinceReboot (s since the phone booted) * 1e9: absolute time "
                     "unknown (the location columns are not read)",
        "acc_from": f"accelerometerAccelerationX/Y/Z (g, iOS sign) * -{STANDARD_GRAVITY_M_S2} m/s^2",
        "repeated_rows": repeated,
        **notes,
    }
    rec = Recording(streams, metadata=meta, repairs=repairs, source=path)
    rec.device = {"app": "SensorLog", "platform": "ios"}
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=2)
    return finish(rec, warn=warn)


def _read_values(text, where: str, repairs: list[str]) -> dict:
    with np.errstate(all="ignore"):
        table = Table(text, where, ",")
        if table.blank:
            raise RecordingError("empty file", where)
        bare = [_bare(h) for h in table.header]
        cols, which = [], []
        for name, (t, xyz) in SENSORS.items():
            names = [t, *xyz]
            if all(n.lower() in bare for n in names):
                which.append(name)
                cols += [(bare.index(n.lower()), "f") for n in names]
            elif name == ACC:
                raise RecordingError(f"{WHAT}: missing column(s) "
                                     f"{', '.join(n for n in names if n.lower() not in bare)}", where, 1)
        out = table.read(cols)
    skip_bad_lines(table.bad, table.n_lines, where, repairs)
    if table.dropped_tail is not None:
        repairs.append(f"{where}: dropped an incomplete last line {table.dropped_tail} (no newline: the file was cut "
                       "off mid-write)")
    v = out["v"]
    return {name: v[:, 4 * i:4 * i + 4] for i, name in enumerate(which)}
