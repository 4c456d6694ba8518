"""Reader for an Oxford Inertial Odometry Dataset sequence (OxIOD; Chen et al. 2018, arXiv:1809.07491): a ``syn``
pair ``imuK.csv`` + ``viK.csv``.

Format (the dataset's ``ReadMe.txt``)
=====================================
Both files are headerless, ``,``-separated, one row per sample; in ``syn/`` the two files have the same number of
rows and row ``i`` of one is row ``i`` of the other ("synchronised data but without high precise timestep").

``imuK.csv`` (16 fields; an iPhone's Core Motion ``CMDeviceMotion`` at 100 Hz)::

    Time, attitude_roll, attitude_pitch, attitude_yaw (rad), rotation_rate_x/y/z (rad/s),
    gravity_x/y/z (g), user_acc_x/y/z (g), magnetic_field_x/y/z (uT)

``viK.csv`` (9 fields; the Vicon motion capture of the phone)::

    Time, Header, translation.x/y/z (m), rotation.x/y/z/w (quaternion, scalar last)

Time
    The ``syn`` files' ``Time`` column is not a usable clock (the copies read ``1.50E+11`` on every row: the
    value was written with three significant digits), so the reader does not read it: ``t_ns = round(i * 1e9 /
    rate_hz)`` for row ``i``, at the dataset's stated 100 Hz (``rate_hz``).  Checked: the rows of the sequences
    copied (``/work/extra_data2``) over 100 Hz give the durations of the dataset's own table (pocket data1
    seq5: 24045 rows, 240 s).  This is the one place where a nominal rate makes the time.
Acceleration
    Core Motion's total acceleration is ``gravity + userAcceleration`` (Apple's documentation of
    ``CMDeviceMotion.gravity`` and ``.userAcceleration``: "The total acceleration of the device is equal to
    gravity plus the acceleration the user imparts to the device"), in g, with iOS's sign: at rest, screen up,
    ``gravity = (0, 0, -1)`` (it points to the ground).  The project's accelerometer reads the specific force
    (screen up ``+9.8``), so ``acc = -9.80665 * (gravity + user_acc)`` -- the same sign flip as
    :mod:`core.importers.sensorlog`, and the same unit check after it
    (:func:`core.importers._common.acceleration_in_m_s2`: a median ``|a|`` of about 9.8 m/s^2).  The device axes are the same as Android's (x right, y to the top edge,
    z out of the screen).
Angular rate, magnetic field
    ``rotation_rate`` (rad/s, right-handed, Core Motion's bias-corrected rate) and ``magnetic_field`` (uT, Core
    Motion's calibrated field) are kept as they are.  The attitude angles are not read.  Core Motion updates the
    field at about half the row rate, so about half the rows repeat the previous row's field exactly (12,014 of
    24,045 in ``pocket/data1/syn/imu5.csv``, 12,031 kept): such a row is not a new measurement (fed to the attitude filter, it
    would count one twice) and is dropped -- the first row of each run of equal vectors is kept -- counted in
    ``metadata["mag_repeats_dropped"]``.
Truth
    ``posi`` (columns ``east_m, north_m, up_m``): the Vicon translation ``(x, y, z)`` of every row.  The Vicon
    frame has z up (the phone's height in a trouser pocket reads about 0.9 m); its x and y are taken as a
    right-handed horizontal pair in an unknown rotation about the vertical (not geographic East and North):
    compare headings through offsets and tracks after a rotation.  ``truth_body_attitude``
    (:data:`core.importers._common.TRUTH_BODY_ATTITUDE`, ``w, x, y, z``): the Vicon quaternion ``rotation.x/y/z/w``
    of the marker body (a row whose norm is not within 1 % of 1 is dropped).  The marker body's axes are not the
    phone's (its tilt disagrees with Core Motion's gravity by 45-170 deg on the copies); the constant rotation
    between them is fitted where needed (:func:`benchmarks.truth_walks.device_attitude`, issue #25).

Both files are read as a stream (:func:`core.importers._csv.fixed_rows`).  A row of either file that is not 16 (9)
numbers is a bad line: it stays in place as a gap (the rows must stay aligned) and is counted in ``repairs``; more
than :func:`core.recording.bad_lines_tolerated` allows is a :class:`RecordingError`.  A last line without its
newline is read when it has all its fields, else it is a gap (a file cut off mid-write, said in ``repairs``).
Files of different row counts are a :class:`RecordingError`.

Streams: ``acc``, ``gyro``, ``mag``, ``posi``, ``truth_body_attitude``.

Detection (:func:`core.importers.detect_format`)
================================================
The files have no header, so the content is tested conservatively (:func:`looks_like`): the first line, and at least
3 and nine in ten of the first 20, are 16 numbers; the attitude angles are within +-pi (pitch +-pi/2); the gravity
columns are Core Motion's unit vector (median norm 0.97-1.03 g, every row 0.9-1.1 g; the copies read 1.0); the
rotation rates are under 35 rad/s. No other format read here has 16 fields a line. The name must then be
``imu<K>.csv`` (``.gz`` allowed): the truth ``vi<K>.csv`` is found by it, and a matching file of another name is
refused saying so. ``vi<K>.csv`` itself (9 numbers a line, a unit quaternion in the last four:
:func:`looks_like_vicon`) is refused pointing at the ``imu<K>.csv`` beside it. A folder holding one ``imu<K>.csv``
of this content (top level only, e.g. a ``syn`` folder with one pair) is read through it; with several, replay one
file (``pdr replay`` given such a folder replays each). Zip archives are not read.
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
from core.importers._common import (
    POSI, TRUTH_BODY_ATTITUDE, acceleration_in_m_s2, feed_lines, finish, head_bytes, head_lines, open_text,
)
from core.importers._csv import ColumnBuffer, fixed_rows

FORMAT = "oxiod"
#: the dataset's sampling rate (its paper and README: "recorded by smartphones at 100 Hz")
RATE_HZ = 100.0
IMU_FIELDS = 16
VI_FIELDS = 9
#: column slices of imuK.csv
ROTATION_RATE = slice(4, 7)
GRAVITY = slice(7, 10)
USER_ACC = slice(10, 13)
MAGNETIC_FIELD = slice(13, 16)
#: column slices of viK.csv: the translation and the rotation (quaternion x, y, z, w: scalar last)
TRANSLATION = slice(2, 5)
ROTATION_XYZW = slice(5, 9)
POSI_COLUMNS = ["east_m", "north_m", "up_m"]
_IMU_NAME = re.compile(r"^imu(\d+)\.csv(\.gz)?$", re.IGNORECASE)
_VI_NAME = re.compile(r"^vi(\d+)\.csv(\.gz)?$", re.IGNORECASE)


def _numeric_rows(head: str, n_fields: int) -> np.ndarray | None:
    """The first lines of ``head`` that are ``n_fields`` numbers, if the first line and at least 3, and nine in ten,
    of them are (the files have no header line)."""
    lines = head_lines(head)
    rows = []
    for i, ln in enumerate(lines):
        parts = ln.strip().split(",")
        try:
            if len(parts) != n_fields:
                raise ValueError
            rows.append([float(p) for p in parts])
        except ValueError:
            if i == 0:
                return None
    if len(rows) < max(3, 0.9 * len(lines)):
        return None
    v = np.asarray(rows, dtype=np.float64)
    return v if np.all(np.isfinite(v)) else None


def looks_like(head: str) -> bool:
    """True if the first lines of a text are rows of an ``imuK.csv`` (see the module doc, *Detection*)."""
    v = _numeric_rows(head, IMU_FIELDS)
    if v is None:
        return False
    roll, pitch, yaw = v[:, 1], v[:, 2], v[:, 3]
    g = np.linalg.norm(v[:, GRAVITY], axis=1)
    return bool(np.all(np.abs(roll) <= np.pi + 1e-3) and np.all(np.abs(pitch) <= np.pi / 2 + 1e-3)
                and np.all(np.abs(yaw) <= np.pi + 1e-3) and 0.97 <= np.median(g) <= 1.03
                and np.all((g > 0.9) & (g < 1.1)) and np.all(np.abs(v[:, ROTATION_RATE]) < 35.0))


def looks_like_vicon(head: str) -> bool:
    """True if the first lines of a text are rows of a ``viK.csv``: 9 numbers, a unit quaternion in the last four."""
    v = _numeric_rows(head, VI_FIELDS)
    return v is not None and bool(np.all(np.abs(np.linalg.norm(v[:, 5:9], axis=1) - 1.0) < 0.05))


def is_imu_name(path: str) -> bool:
    """The name is ``imu<K>.csv`` (or ``.csv.gz``)."""
    return _IMU_NAME.match(os.path.basename(str(path))) is not None


def imu_partner(vi_path: str) -> str | None:
    """The ``imuK.csv`` beside a ``viK.csv`` when it exists, else None."""
    folder, name = os.path.split(str(vi_path))
    m = _VI_NAME.match(name)
    if not m:
        return None
    imu = os.path.join(folder, f"imu{m.group(1)}.csv{m.group(2) or ''}")
    return imu if os.path.isfile(imu) else None


def imu_files(folder: str) -> list[str]:
    """The ``imuK.csv`` files at the top of ``folder`` whose content :func:`looks_like` accepts (sorted by K)."""
    if not os.path.isdir(folder):
        return []
    found = []
    for name in os.listdir(folder):
        m = _IMU_NAME.match(name)
        full = os.path.join(folder, name)
        if m and os.path.isfile(full):
            try:
                head = head_bytes(full, 65536)
            except OSError:
                continue
            if looks_like(head.decode("utf-8", errors="replace")):
                found.append((int(m.group(1)), full))
    return [f for _, f in sorted(found)]


def vicon_path(imu_path: str) -> str:
    """The ``viK.csv`` beside an ``imuK.csv`` (same folder, same K); a :class:`RecordingError` for another name."""
    folder, name = os.path.split(str(imu_path))
    m = _IMU_NAME.match(name)
    if not m:
        raise RecordingError("not an OxIOD sensor file: the name is not imu<K>.csv", str(imu_path))
    return os.path.join(folder, f"vi{m.group(1)}.csv{m.group(2) or ''}")


def _rows(path: str, n_fields: int, repairs: list[str], limit: int | None) -> np.ndarray:
    """Every non-blank line of a headerless numeric CSV as a row of ``n_fields`` floats, streamed
    (:func:`core.importers._csv.fixed_rows`; a bad line, or a last line cut off without its newline: a row of nan,
    so that the two files stay aligned)."""
    out = ColumnBuffer(n_fields)
    bad: list[RecordingError] = []
    n_lines = 0

    def chunk(first: int, lines: list[str]) -> None:
        nonlocal n_lines
        nos = [first + j for j, ln in enumerate(lines) if ln.strip()]
        rows = [ln for ln in lines if ln.strip()]
        if not rows:
            return
        n_lines += len(rows)
        _, v, kept, errs = fixed_rows(rows, list(range(n_fields)), ",", (n_fields, n_fields), int_first=False)
        bad.extend(RecordingError(msg, path, nos[j]) for j, msg in errs)
        if not kept.all():
            v, full = np.full((len(rows), n_fields), np.nan), v
            v[kept] = full
        out.append(v)

    def tail(lineno: int, last: str) -> None:
        if not last.strip():
            return
        if last.count(",") + 1 == n_fields:
            chunk(lineno, [last])
        else:
            out.append(np.full((1, n_fields), np.nan))
            repairs.append(f"{path}: the last line {lineno} (no newline, {last.count(',') + 1} of {n_fields} "
                           "fields) was cut off mid-write: a gap")

    with open_text(path, repairs, limit) as text:
        feed_lines(text, path, repairs, chunk, bad, tail)
    skip_bad_lines(bad, n_lines, path, repairs)
    if not len(out):
        raise RecordingError("empty file", path)
    return out.array()


def read_oxiod(path: str, *, rate_hz: float = RATE_HZ, warn: bool = True,
               max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read an OxIOD ``syn`` pair from its ``imuK.csv`` (the ``viK.csv`` beside it is the truth; see the module doc)."""
    path = str(path)
    if not os.path.isfile(path):
        raise RecordingError("cannot open: no such file", path)
    vi_path = vicon_path(path)
    repairs: list[str] = []
    imu = _rows(path, IMU_FIELDS, repairs, max_uncompressed_bytes)
    vi = _rows(vi_path, VI_FIELDS, repairs, max_uncompressed_bytes) if os.path.isfile(vi_path) else None
    if vi is not None and len(vi) != len(imu):
        raise RecordingError(f"{len(imu)} sensor rows but {len(vi)} Vicon rows in {os.path.basename(vi_path)}: a "
                             "syn pair has one row of each per sample", path)
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
    t_ns = np.round(np.arange(len(imu)) * (1e9 / rate_hz)).astype(np.int64)
    ok = np.all(np.isfinite(imu[:, 1:]), axis=1)
    if not ok.any():
        raise RecordingError("no sensor row", path)
    notes: dict = {}
    acc = acceleration_in_m_s2(-STANDARD_GRAVITY_M_S2 * (imu[ok, GRAVITY] + imu[ok, USER_ACC]),
                               "gravity + user_acc", path, repairs, notes)
    mag, mag_t = imu[ok, MAGNETIC_FIELD], t_ns[ok]
    new = np.ones(len(mag), dtype=bool)
    new[1:] = np.any(mag[1:] != mag[:-1], axis=1)  # Core Motion's field, updated at about half the row rate
    streams = {
        ACC: make_stream(ACC, t_ns[ok], acc, note="Core Motion gravity + userAcceleration (g, iOS sign) * -g0"),
        GYRO: make_stream(GYRO, t_ns[ok], imu[ok, ROTATION_RATE], note="Core Motion rotationRate (bias-corrected)"),
        MAG: make_stream(MAG, mag_t[new], mag[new], note="Core Motion calibrated magnetic field, a row repeating "
                                                         "the previous field exactly dropped"),
    }
    if vi is not None:
        good = np.all(np.isfinite(vi[:, TRANSLATION]), axis=1)
        streams[POSI] = make_stream(POSI, t_ns[good], vi[good, TRANSLATION], POSI_COLUMNS, "m,m,m",
                                    "ground truth: Vicon translation of the phone at every row (x, y, z); z up, "
                                    "x and y a horizontal pair in the room's frame, not geographic")
        q = vi[:, ROTATION_XYZW][:, [3, 0, 1, 2]]  # w, x, y, z
        good = np.all(np.isfinite(q), axis=1) & (np.abs(np.linalg.norm(q, axis=1) - 1.0) < 0.01)
        streams[TRUTH_BODY_ATTITUDE] = make_stream(TRUTH_BODY_ATTITUDE, t_ns[good], q[good], ["w", "x", "y", "z"], "1",
                                                   "ground truth: the Vicon rotation (x, y, z, w) of the marker body, "
                                                   "body -> the frame of posi; the body's axes are not the phone's "
                                                   "(their tilt disagrees with Core Motion's gravity by 45-170 deg)")
    meta = {
        "source_format": FORMAT,
        "app": "OxIOD (Core Motion device motion, iPhone; Vicon truth)",
        "time_base": f"t_ns = row * 1e9 / {rate_hz:g} Hz: the syn files' Time column is not a usable clock "
                     "(absolute time unknown)",
        "acc_from": f"(gravity + user_acc) (g, iOS sign) * -{STANDARD_GRAVITY_M_S2} m/s^2",
        "truth_file": os.path.basename(vi_path) if vi is not None else None,
        "mag_repeats_dropped": int((~new).sum()),
        **notes,
    }
    if warn and repairs:
        warnings.warn("; ".join(repairs), DamagedFileWarning, stacklevel=2)
    return finish(Recording(streams, device={"app": "OxIOD", "platform": "ios"}, metadata=meta, repairs=repairs,
                            source=path), warn=warn)
