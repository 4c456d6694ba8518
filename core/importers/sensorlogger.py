"""Reader for Sensor Logger exports (the iOS/Android app by Kelvin Choi, tszheichoi).

Input: the exported zip, or the folder it unpacks to (files may also be
``name.csv.gz``), or any one CSV inside such a folder (the folder is read).
One CSV per sensor, a header line, comma-separated numbers::

    time,seconds_elapsed,z,y,x                     (Accelerometer, Gravity, Gyroscope, Magnetometer, ...)
    time,seconds_elapsed,qz,qy,qx,qw,roll,pitch,yaw                              (Orientation)
    time,seconds_elapsed,horizontalAccuracy,speed,bearing,altitude,longitude,latitude (Location; newer
            versions add speedAccuracy, bearingAccuracy, verticalAccuracy, altitudeAboveMeanSeaLevel)
    time,seconds_elapsed,relativeAltitude,pressure                              (Barometer)

Columns are found by name, so their order does not matter.  ``Metadata.csv``
(one header and one row: version, device name, recording time, platform,
appVersion, ...) gives the platform.

Facts used (Sensor Logger documentation, awesome-sensor-logger UNITS.md,
COORDINATES.md, CROSSPLATFORM.md, ORIENTATION.md; checked on the v1.12
Android recording in ``../shared/data/sensorlogger_gps_walk_ethz`` and the
v1.15.2 iOS walk ``siberiawolfp_walking2`` in ``../shared/data/gps_walks_phone``)
================================================================================
Time
    ``time`` is integer nanoseconds since the Unix epoch, ``seconds_elapsed``
    seconds since the recording started; on the ETH file ``time -
    seconds_elapsed * 1e9`` is one constant (the start, with ms resolution)
    within float rounding (+-250 ns) across all files, and every stream is
    strictly increasing.  Here ``t_ns = time - start_ns`` (nanoseconds since
    the recording started, keeping the exact ``time`` differences) and
    ``metadata["unix_offset_ns"] = start_ns`` (``unix_ns = t_ns + unix_offset_ns``).
Android (platform "android")
    Every sensor is in the Android device frame and Android units.
    ``TotalAcceleration.csv`` is ``TYPE_ACCELEROMETER`` (m/s^2 with gravity)
    and is taken as ``acc`` unchanged; ``Accelerometer.csv`` is the linear
    acceleration (gravity removed) and ``Gravity.csv`` the OS gravity
    estimate -- their sum is used when TotalAcceleration is missing.
    Gyroscope rad/s, Magnetometer uT, both calibrated by the OS; the
    ``*Uncalibrated.csv`` files become ``gyro_uncal`` / ``mag_uncal``.
    Orientation is ``TYPE_ROTATION_VECTOR``: ``(qw, qx, qy, qz)`` rotates
    device vectors into East-North-Up (magnetic north); its ``yaw`` is the
    Android azimuth (clockwise), ``pitch = asin(-R[2,1])``, ``roll =
    atan2(-R[2,0], R[2,2])`` -- checked on a public Android sample row.
iOS (platform "ios"), default settings
    Accelerometer.csv is the user acceleration (gravity removed, CoreMotion
    ``userAcceleration``) and Gravity.csv the gravity, both already
    converted to m/s^2 by the app, but **with the opposite sign on all three
    axes** (CoreMotion reports the inertial force: flat and still, gravity
    reads -z on iOS and +z on Android).  So ``acc = -(Accelerometer +
    Gravity)``.  AccelerometerUncalibrated.csv is in g, also negated:
    ``acc = -9.80665 * raw`` (used only when nothing better exists).
    Gyroscope (rad/s) and Magnetometer (uT) have the same axes and signs as
    Android and are copied.  Checked on the 1.15.2 walk: the result matches
    ``-9.80665 * AccelerometerUncalibrated`` within 0.15 m/s^2 (median), the
    gyroscope explains how the magnetometer's field turns (slope 0.99) and
    the field points down (dip 57 deg, the Netherlands).  Orientation is
    CoreMotion's attitude in the ``xTrueNorthZVertical`` frame: ``q`` rotates
    device vectors into a North-West-Up frame referenced to **true** north
    (yaw 0 when the device x axis points north, counter-clockwise positive).
    ENU<-device is ``qz(+90 deg) (x) q``.
iOS with "Standardise Units & Frames" (app >= 1.29)
    The app already converts to the Android definitions (acc sign, units).
    It is recognised by a Metadata.csv column whose name contains
    "standardis"/"standardiz" with a true value; otherwise the default is
    assumed.
Location (both platforms)
    ``gps`` = latitude, longitude, altitude (WGS-84 ellipsoid), horizontalAccuracy,
    speed (m/s), bearing (deg clockwise from true north).  A negative value
    means invalid (nan), as does a speed or bearing whose ``speedAccuracy``
    / ``bearingAccuracy`` is negative; a bearing of exactly 0 is Android's
    "no bearing" (nan; on the ETH walk it comes only with speeds near 0).
    The two accuracies are not stream columns: their medians are
    ``metadata["gps_speedAccuracy_median"]`` / ``["gps_bearingAccuracy_median"]``.
    Fixes stamped before the recording started (negative
    ``seconds_elapsed``: the phone's cached last location, two on the iOS
    1.15 walk of ``../shared/data/gps_walks_phone``) are dropped and noted in
    ``repairs``.
Checks made on the data (results in ``metadata``)
    * the acceleration magnitude must be about 1 g: a median |acc| near 1
      means the values are in g (converted, noted in ``repairs``); anything
      else not near 9.8 m/s^2 is a :class:`RecordingError`, except a swinging
      phone's (see :func:`core.importers._common.acceleration_in_m_s2`);
    * the orientation convention is verified against the accelerometer (the
      quaternion must turn the measured up vector to ENU up) and the
      magnetometer (device-y bearing from the quaternion vs. the
      tilt-compensated compass); if the platform's documented convention
      fails and another (conjugate, or the other frame) passes, that one is
      used and the switch is noted in ``repairs``;
    * ``metadata["mag_dip_deg"]``: the field's inclination below the horizon
      (positive in the northern hemisphere); a sign error would flip it;
    * ``metadata["gps_check"]``: reported speed and course against the
      fixes' own track (:func:`core.importers._common.gps_check`).
Cannot be converted (:class:`RecordingError`)
    linear acceleration without gravity (Accelerometer.csv with no Gravity.csv
    or TotalAcceleration.csv); an unknown platform when the signs depend on it
    (no Metadata.csv and no TotalAcceleration.csv: pass ``platform=`` or set the environment variable
    ``PDR_SENSORLOGGER_PLATFORM``).
A missing (or empty) Gyroscope.csv or Magnetometer.csv
    The uncalibrated file is used for ``gyro`` / ``mag``, with a line in
    ``repairs`` and a :class:`core.recording.SensorSubstitutedWarning`.
Damaged files
    A bad line (a field missing or not a number) is skipped and counted,
    or, past 100 or 1 % of a file's lines, a :class:`RecordingError` naming
    the first; a last line without its newline (the app ends every line
    with one) was cut and is dropped; both with a
    :class:`core.recording.DamagedFileWarning`.
"""

from __future__ import annotations

import math
import os
import warnings

import numpy as np

from core import quaternion as quat
from core.conventions import ACC, GPS, GYRO, MAG, ROTVEC, STANDARD_GRAVITY_M_S2
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, SensorSubstitutedWarning, make_stream,
    skip_bad_lines,
)
from core.importers._common import (
    EXTRA_STREAM_SPECS, GYRO_UNCAL, MAG_UNCAL, PRESSURE, FileSet, acceleration_in_m_s2, attitude_checks, finish,
    gps_check, gps_values, magnetic_dip_deg, sample_at,
)
from core.importers._csv import Table, csv_rows

FORMAT = "sensorlogger"

#: environment variable naming the platform ("android" or "ios") of an export without Metadata.csv
#: (the ``platform`` argument of :func:`read_sensorlogger` takes precedence)
PLATFORM_ENV = "PDR_SENSORLOGGER_PLATFORM"

#: files this reader uses (lower-case base name without .csv)
KNOWN = ("accelerometer", "totalacceleration", "gravity", "gyroscope", "gyroscopeuncalibrated", "magnetometer",
         "magnetometeruncalibrated", "accelerometeruncalibrated", "orientation", "location", "barometer", "metadata")

HEADER_START = "time,seconds_elapsed"


def looks_like_csv(head: str) -> bool:
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip().lower()
    return first.startswith(HEADER_START)


def looks_like_metadata(head: str) -> bool:
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip().lower()
    return "platform" in first and ("appversion" in first or "device name" in first)


def _recording_files(fs: FileSet) -> dict[str, str]:
    """lower-case base name -> name in the file set, for one recording."""
    by_base: dict[str, list[str]] = {}
    for name in fs.names():
        base = name.split("/")[-1]
        if base.lower().endswith(".csv"):
            by_base.setdefault(base[:-4].lower(), []).append(name)
    dup = {b: n for b, n in by_base.items() if len(n) > 1 and b in KNOWN}
    if dup:
        folders = sorted({n.rsplit("/", 1)[0] if "/" in n else "." for ns in dup.values() for n in ns})
        raise RecordingError(f"holds several Sensor Logger recordings (folders {', '.join(folders)}); "
                             f"read one folder at a time", fs.path)
    return {b: n[0] for b, n in by_base.items()}


def _read_metadata(fs: FileSet, name: str | None) -> dict:
    """Metadata.csv: a header and one row (values may be quoted and contain commas)."""
    if name is None:
        return {}
    rows = [r for r in csv_rows(fs.read_text(name), fs.where(name)) if r]
    if len(rows) < 2:
        return {}
    head, row = rows[0], rows[1]
    return {h.strip(): (row[i].strip() if i < len(row) else "") for i, h in enumerate(head)}


#: the value columns read from each file (lower-case base name): required ones, and optional ones (an empty
#: field is nan); files not listed hold x, y, z
_COLUMNS = {
    "orientation": (("qw", "qx", "qy", "qz"), ()),
    "location": (("latitude", "longitude"),
                 ("altitude", "horizontalAccuracy", "speed", "bearing", "speedAccuracy", "bearingAccuracy")),
    "barometer": (("pressure",), ()),
}


class _Sensor:
    """One Sensor Logger CSV: times and named value columns, read once as a stream.

    A bad line (a field missing or not a number) is skipped and counted
    under the one rule of :func:`core.recording.skip_bad_lines`, with a line
    in ``repairs`` and a :class:`core.recording.DamagedFileWarning`.
    """

    def __init__(self, fs: FileSet, name: str, base: str, repairs: list[str], warn: bool):
        self.where = fs.where(name)
        with fs.text(name) as text:
            # the app ends every line with a newline: a last line without one was cut, maybe inside a number
            table = Table(text, self.where, cut_tail=True)
            self.table = None if table.blank else table  # the app leaves a 0-byte file for a sensor without data
            self.empty = table.blank
            if self.empty:
                return
            ti = table.require(["time"], "Sensor Logger file")[0]
            si = table.index("seconds_elapsed")
            strict, optional = _COLUMNS.get(base, (("x", "y", "z"), ()))
            self._names = [c for c in strict + optional if table.index(c) is not None]
            cols = [(ti, "i")] + [(table.index(c), "f" if c in strict else "o") for c in self._names]
            # seconds_elapsed only fixes the recording start: the first rows suffice
            data = table.read(cols, head_cols=[si] if si is not None else [], head_rows=2000)
        n_repairs = len(repairs)
        skip_bad_lines(table.bad, table.n_lines, self.where, repairs)
        if warn:
            for r in repairs[n_repairs:]:
                warnings.warn(r, DamagedFileWarning, stacklevel=4)
        self.time = data["t"]
        self._values = data["v"]
        self.empty = len(self.time) == 0
        self.elapsed = data["head"][:, 0] if si is not None else None

    def cols(self, names: list[str], optional: bool = False) -> np.ndarray:
        """Columns ``names`` (n, len(names)); a column the file lacks is an error naming it."""
        self.table.require(names, "Sensor Logger file")
        pos = [next(k for k, c in enumerate(self._names) if c.lower() == n.lower()) for n in names]
        if pos == list(range(pos[0], pos[0] + len(pos))):
            return self._values[:, pos[0]:pos[0] + len(pos)]  # a view, no copy
        return self._values[:, pos]

    def xyz(self) -> np.ndarray:
        # Sensor Logger writes z, y, x; take them by name
        return self.cols(["x", "y", "z"])


def _location(s: _Sensor, t_ns: np.ndarray, notes: dict, repairs: list[str]):
    """Location.csv -> the ``gps`` stream (speed and course from ``speed`` and ``bearing``).

    A negative value is invalid (Sensor Logger's documentation; iOS writes
    -1), and so is a speed or bearing whose ``speedAccuracy`` /
    ``bearingAccuracy`` is negative.  The two accuracies have no column in
    the stream: their medians go to ``notes``.  Fixes stamped before the
    recording started (the phone's cached last location, delivered at the
    start: two on an iOS 1.15 walk, 24 and 14 s early) are dropped.
    """
    def opt(name):
        return s.cols([name], optional=True)[:, 0] if s.table.index(name) is not None else None

    lat, lon = s.cols(["latitude", "longitude"]).T
    speed, course = opt("speed"), opt("bearing")
    for value, acc_name in ((speed, "speedAccuracy"), (course, "bearingAccuracy")):
        acc = opt(acc_name)
        if acc is not None:
            if value is not None:
                value[acc < 0] = np.nan
            good = acc[acc >= 0]
            notes[f"gps_{acc_name}_median"] = float(np.median(good)) if len(good) else None
    values = gps_values(lat, lon, opt("altitude"), opt("horizontalAccuracy"), speed, course)
    early = t_ns < 0
    if early.any():
        repairs.append(f"{s.where}: dropped {int(early.sum())} fix(es) stamped before the recording started "
                       f"({t_ns[early].min() * 1e-9:.1f} to {t_ns[early].max() * 1e-9:.1f} s: the phone's cached "
                       "last location)")
        t_ns, values = t_ns[~early], values[~early]
    kept = [n for n in ("speedAccuracy", "bearingAccuracy") if s.table.index(n) is not None]
    note = ("GNSS/fused location (Sensor Logger Location.csv); alt_m above the WGS-84 ellipsoid; hacc_m = "
            "horizontalAccuracy; speed_m_s = speed, course_deg = bearing (negative = invalid = nan; a bearing "
            "of exactly 0 is Android's 'no bearing' = nan)")
    if kept:
        note += f"; {' and '.join(kept)} are not in the stream (medians in the metadata)"
    return make_stream(GPS, t_ns, values, note=note)


def read_sensorlogger(path: str, *, platform: str | None = None, warn: bool = True,
                      max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a Sensor Logger export (zip, folder, or a CSV inside the folder); see the module doc.

    ``platform`` ("android" or "ios") overrides or replaces Metadata.csv;
    the environment variable ``PDR_SENSORLOGGER_PLATFORM`` stands in for a
    Metadata.csv without a platform (so that the command line can say it),
    never overriding one.  Each file is streamed; a zip member (or gzip
    file) of over ``max_uncompressed_bytes`` is refused before it is read.
    """
    path = str(path)
    if not os.path.exists(path):
        raise RecordingError("cannot open: no such file or folder", path)
    root = path
    if os.path.isfile(path) and path.lower().endswith((".csv", ".csv.gz")):
        root = os.path.dirname(os.path.abspath(path))
    # non-finite values pass through as data, without numpy warnings
    with FileSet(root, max_uncompressed_bytes) as fs, np.errstate(all="ignore"):
        return _read(fs, root, platform, warn)


def _read(fs: FileSet, source: str, platform_arg: str | None, warn: bool) -> Recording:
    files = _recording_files(fs)
    if not any(k in files for k in KNOWN if k != "metadata"):
        raise RecordingError("no Sensor Logger sensor files (Accelerometer.csv, Gyroscope.csv, ...) found", source)
    md = _read_metadata(fs, files.get("metadata"))
    repairs: list[str] = []
    sensors: dict[str, _Sensor] = {}
    for base in KNOWN:
        if base in files and base != "metadata":
            s = _Sensor(fs, files[base], base, repairs, warn)
            if s.table is not None and s.table.dropped_tail:
                repairs.append(f"{s.where}: dropped an incomplete last line {s.table.dropped_tail} (no newline: "
                               "the recording was cut off mid-write; its last number may be cut short)")
                if warn:
                    warnings.warn(repairs[-1], DamagedFileWarning, stacklevel=3)
            if not s.empty:
                sensors[base] = s
    for r in fs.repairs:  # gzip members cut part-way
        repairs.append(r)
        if warn:
            warnings.warn(r, DamagedFileWarning, stacklevel=3)
    if not sensors:
        raise RecordingError("no usable sensor data (all Sensor Logger files empty?)", source)
    ignored = sorted(files[b].split("/")[-1] for b in files if b not in KNOWN)
    empty = sorted(files[b].split("/")[-1] for b in files if b in KNOWN and b != "metadata" and b not in sensors)

    # -- platform and sign convention
    # the argument overrides Metadata.csv; the environment variable only stands in for a missing one
    env = os.environ.get(PLATFORM_ENV, "").strip()
    md_platform = md.get("platform", "").strip()
    platform = (platform_arg or md_platform or env).strip().lower()
    if platform in ("iphone", "ipados", "watchos"):
        platform = "ios"
    if not platform:
        if "totalacceleration" in sensors:
            platform = "android"  # only the Android app writes TotalAcceleration.csv
        else:
            raise RecordingError("cannot tell whether this was recorded on iOS or Android (no Metadata.csv and no "
                                 "TotalAcceleration.csv), and the acceleration sign depends on it; set the "
                                 f"environment variable {PLATFORM_ENV}=android or {PLATFORM_ENV}=ios (from Python: "
                                 "read_sensorlogger/load_recording(..., platform='android'|'ios'))", source)
    if platform not in ("android", "ios"):
        where = "the platform argument" if platform_arg else ("Metadata.csv" if md_platform else PLATFORM_ENV)
        raise RecordingError(f"unknown platform {platform!r} in {where} (expected android or ios)", source)
    standardised = any(("standardis" in k.lower() or "standardiz" in k.lower())
                       and v.strip().lower() in ("true", "1", "yes", "on") for k, v in md.items())
    ios_native = platform == "ios" and not standardised
    # iOS (default settings) reports acceleration and gravity as inertial force: every axis negated
    acc_sign = -1.0 if ios_native else 1.0

    # -- time base: nanoseconds since the recording started
    offsets = []
    for s in sensors.values():
        ok = np.isfinite(s.elapsed) & (np.abs(s.elapsed) < 1e9) if s.elapsed is not None else None
        if ok is not None and ok.any():
            d = s.time[:len(s.elapsed)][ok] - np.rint(s.elapsed[ok] * 1e9).astype(np.int64)
            offsets.append(int(np.median(d - d.min())) + int(d.min()))
    if offsets:
        start_ns = int(np.median(np.array(offsets, dtype=np.int64) - min(offsets))) + min(offsets)
        time_source = "time - seconds_elapsed (recording start, Unix ns)"
    else:
        start_ns = min(int(s.time[0]) for s in sensors.values())
        time_source = "first 'time' value (no seconds_elapsed column)"

    def t_of(s: _Sensor) -> np.ndarray:
        return s.time - start_ns

    streams = {}
    notes = {}
    # -- acceleration, gravity included, Android sign
    if "totalacceleration" in sensors:
        s = sensors["totalacceleration"]
        acc_t, acc_v = t_of(s), acc_sign * s.xyz()
        notes["acc_from"] = "TotalAcceleration.csv"
    elif "accelerometer" in sensors and "gravity" in sensors:
        s, g = sensors["accelerometer"], sensors["gravity"]
        lin, grav = s.xyz(), g.xyz()
        if len(g.time) == len(s.time) and np.array_equal(g.time, s.time):
            grav_at = grav
        else:
            grav_at = sample_at(g.time, grav, s.time)  # gravity is smooth: interpolate to the acc times
        acc_t, acc_v = t_of(s), acc_sign * (lin + grav_at)
        notes["acc_from"] = "Accelerometer.csv + Gravity.csv"
    elif "accelerometeruncalibrated" in sensors:
        s = sensors["accelerometeruncalibrated"]
        scale = -STANDARD_GRAVITY_M_S2 if ios_native else 1.0  # iOS: g and inertial sign
        acc_t, acc_v = t_of(s), scale * s.xyz()
        notes["acc_from"] = "AccelerometerUncalibrated.csv"
    elif "accelerometer" in sensors:
        s = sensors["accelerometer"]
        v = s.xyz()
        m = float(np.median(np.linalg.norm(v, axis=1)))
        if not (0.6 * STANDARD_GRAVITY_M_S2 < m < 1.4 * STANDARD_GRAVITY_M_S2):
            raise RecordingError("Accelerometer.csv is acceleration without gravity (median |a| = "
                                 f"{m:.2f} m/s^2) and there is no Gravity.csv or TotalAcceleration.csv to "
                                 "restore it; the pipeline needs acceleration including gravity", source)
        acc_t, acc_v = t_of(s), acc_sign * v
        notes["acc_from"] = "Accelerometer.csv (it includes gravity: median |a| = %.2f m/s^2)" % m
    else:
        acc_t = acc_v = None
    if acc_v is not None and len(acc_v):
        acc_v = acceleration_in_m_s2(acc_v, notes["acc_from"], source, repairs, notes)
        streams[ACC] = make_stream(ACC, acc_t, acc_v)

    # -- gyroscope and magnetometer: same axes, signs and units on both platforms
    for cal, uncal, name, extra in (("gyroscope", "gyroscopeuncalibrated", GYRO, GYRO_UNCAL),
                                    ("magnetometer", "magnetometeruncalibrated", MAG, MAG_UNCAL)):
        if cal in sensors:
            s = sensors[cal]
            v, t = s.xyz(), t_of(s)
            if name == MAG:
                # a magnetometer that has no calibration yet can deliver exact zeros: not a field reading
                zero = np.all(v == 0.0, axis=1)
                if zero.any():
                    notes["mag_zero_rows_dropped"] = int(zero.sum())
                    v, t = v[~zero], t[~zero]
            streams[name] = make_stream(name, t, v)
        if uncal in sensors:
            s = sensors[uncal]
            spec = EXTRA_STREAM_SPECS[extra]
            streams[extra] = make_stream(extra, t_of(s), s.xyz(), spec["columns"], spec["unit"], spec["note"])
            if cal not in sensors:
                streams[name] = make_stream(name, t_of(s), s.xyz(),
                                            note=f"uncalibrated ({os.path.basename(s.where)}): no calibrated file")
                notes[f"{name}_from"] = "uncalibrated file"
                what = "the OS gyro bias is not removed" if name == GYRO else "the OS hard-iron correction is missing"
                msg = (f"{source}: no calibrated {cal.capitalize()}.csv (missing or empty): the '{name}' stream is "
                       f"{os.path.basename(s.where)} instead ({what})")
                repairs.append(msg)
                if warn:
                    warnings.warn(msg, SensorSubstitutedWarning, stacklevel=3)

    # -- location
    if "location" in sensors:
        s = sensors["location"]
        streams[GPS] = _location(s, t_of(s), notes, repairs)

    # -- barometer
    if "barometer" in sensors:
        s = sensors["barometer"]
        spec = EXTRA_STREAM_SPECS[PRESSURE]
        streams[PRESSURE] = make_stream(PRESSURE, t_of(s), s.cols(["pressure"]), spec["columns"], spec["unit"],
                                        spec["note"])

    meta: dict = {}
    # -- orientation
    if "orientation" in sensors:
        s = sensors["orientation"]
        qw, qx, qy, qz = s.cols(["qw", "qx", "qy", "qz"]).T
        q_raw = np.column_stack([qw, qx, qy, qz])
        with np.errstate(invalid="ignore", divide="ignore"):
            q_raw = q_raw / np.linalg.norm(q_raw, axis=1, keepdims=True)
        good = np.all(np.isfinite(q_raw), axis=1)
        t_rot = t_of(s)[good]
        q_raw = q_raw[good]
        q_enu, label, check = _orientation_to_enu(platform, standardised, t_rot, q_raw, streams, repairs, source)
        north = "true north" if (platform == "ios" and "NWU" in label) else "magnetic north"
        streams[ROTVEC] = make_stream(ROTVEC, t_rot, q_enu,
                                      note=f"Sensor Logger Orientation.csv as an ENU<-device quaternion "
                                           f"(w, x, y, z); heading relative to {north}")
        meta["rotvec_convention"] = label
        meta["rotvec_north"] = north
        meta["rotvec_check"] = check

    if not streams:
        raise RecordingError("no usable sensor data (all Sensor Logger files empty?)", source)
    if ACC in streams and MAG in streams:
        a, m = streams[ACC], streams[MAG]
        meta["mag_dip_deg"] = magnetic_dip_deg(a.t_ns, a.values, m.t_ns, m.values)
    if GPS in streams and len(streams[GPS]):
        meta["gps_check"] = gps_check(streams[GPS].t_ns, streams[GPS].values)

    device = {"platform": platform, "app": "Sensor Logger"}
    if md.get("device name"):
        device["model"] = md["device name"]
    meta.update({
        "source_format": FORMAT,
        "app": "Sensor Logger",
        "app_version": md.get("appVersion", ""),
        "metadata_version": md.get("version", ""),
        "recording_time": md.get("recording time", ""),
        "standardised_units_frames": standardised,
        "time_base": "t_ns = time - unix_offset_ns (ns since the recording started)",
        "unix_offset_ns": start_ns,
        "unix_time_source": time_source,
        "files_read": sorted(os.path.basename(sensors[b].where) for b in sensors),
        "files_empty": empty,
        "ignored_files": ignored,
        **notes,
    })
    if md.get("sensors") and md.get("sampleRateMs"):
        names = md["sensors"].split("|")
        rates = md["sampleRateMs"].split("|")
        meta["sample_rate_ms"] = {n: r for n, r in zip(names, rates)}
    rec = Recording(streams, device=device, metadata=meta, repairs=repairs, source=source)
    return finish(rec, warn=warn, unix_offset_ns=start_ns)


# ---------------------------------------------------------------------------
# orientation conventions

_QZ90 = quat.about_axis_array(2, np.array(math.pi / 2))  # ENU <- NWU: a +90 deg turn about up


def _candidates(q: np.ndarray) -> dict[str, np.ndarray]:
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    return {
        "q is ENU<-device (Android rotation vector)": q,
        "q is NWU<-device, x true north (iOS CoreMotion xTrueNorthZVertical)": quat.multiply_array(_QZ90, q),
        "conjugate q is ENU<-device": conj,
        "conjugate q is NWU<-device": quat.multiply_array(_QZ90, conj),
    }


def _orientation_to_enu(platform, standardised, t_rot, q_raw, streams, repairs, source):
    cands = _candidates(q_raw)
    keys = list(cands)
    expected = keys[0] if (platform == "android" or standardised) else keys[1]
    acc, mag = streams.get(ACC), streams.get(MAG)
    if acc is None:
        return quat.canonical_sign_array(cands[expected]), expected + " (unverified: no accelerometer)", {}
    checks = {k: attitude_checks(t_rot, v, acc.t_ns, acc.values, mag.t_ns if mag else None,
                                 mag.values if mag else None) for k, v in cands.items()}

    def ok(k, heading_tol):
        c = checks[k]
        tilt_ok = math.isfinite(c["tilt_err_deg"]) and c["tilt_err_deg"] < 15.0
        h = c["heading_diff_deg"]
        return tilt_ok and (not math.isfinite(h) or h < heading_tol)

    chosen = expected
    if not ok(expected, 45.0):
        passing = [k for k in keys if ok(k, 20.0)]
        if passing:
            chosen = passing[0]
            repairs.append(f"{source}: Orientation.csv does not fit the documented {platform} convention "
                           f"({expected}: {checks[expected]}); used '{chosen}', which fits the accelerometer "
                           f"and magnetometer ({checks[chosen]})")
        else:
            repairs.append(f"{source}: Orientation.csv could not be verified against the accelerometer and "
                           f"magnetometer ({checks[expected]}); kept the documented {platform} convention")
    return quat.canonical_sign_array(cands[chosen]), chosen, checks[chosen]
