"""Importers: recordings of other phone apps, converted once at the edge to :mod:`core`'s conventions.

::

    from core.importers import detect_format, load_recording
    fmt = detect_format(path)        # "pdr-recording" | "getsensordata" | "sensorlogger" | "phyphox" | ...
    rec = load_recording(path)       # a core.recording.Recording (t_ns int64, SI, Android axes, ENU quaternions)

Formats (name: input -> reader):

* ``pdr-recording``: this project's file (``.gz`` allowed) -> :func:`core.recording.read_recording`
* ``getsensordata``: GetSensorData / IPIN logfile (``.txt`` or ``.gz``) -> :func:`read_getsensordata`
* ``sensorlogger``: Sensor Logger export, zip or folder (or a CSV inside it) -> :func:`read_sensorlogger`
  (``platform="android"|"ios"``, or the environment variable ``PDR_SENSORLOGGER_PLATFORM``, when the
  export has no Metadata.csv)
* ``phyphox``: phyphox CSV export, zip or folder (or one data CSV) -> :func:`read_phyphox`
* ``msindoor``: Microsoft/XYZ10 Indoor Location Competition trace (``.txt`` or ``.gz``) -> :func:`read_msindoor`
* ``brajdic-harle``: Brajdic & Harle step-counting trace, binary ``.out`` or text ``.dat`` (or ``.gz``)
  -> :func:`read_brajdic`
* ``oxford-step-counter``: Oxford step-counter accelerometer CSV (``.csv`` or ``.gz``, or its folder)
  -> :func:`read_oxford`
* ``trundlewheel``: TrundleWheel raw log (W3C DeviceMotion, ``;``-separated, ``.csv`` or ``.gz``), or the
  authors' 1 Hz resampled ("conditioned") file -> :func:`read_trundle`
* ``x-io``: x-io Technologies NGIMU ``sensors.csv`` (or its session folder/zip) or x-IMU calibrated CSV
  (``.csv`` or ``.gz``) -> :func:`read_xio`
* ``xsens``: XSens text export (``Acquisition frequency`` line, ``PacketCounter Acc_X ...`` header; ``.txt`` or
  ``.gz``); an IPOL trial's lower-back file reads the trial's foot files beside it -> :func:`read_xsens`
* ``physics-toolbox``: Physics Toolbox Sensor Suite g-Force Meter CSV (``time,gFx,gFy,gFz,...``; ``.csv`` or
  ``.gz``, or a folder holding one) -> :func:`read_physicstoolbox`
* ``accel-csv``: an accelerometer CSV ``Timestamp,Milliseconds,X,Y,Z`` (m/s^2 with gravity, Android axes; an
  unnamed Android logger; ``.csv`` or ``.gz``, or a folder holding one) -> :func:`read_accelcsv`
* ``sensibility-testbed``: a Sensibility Testbed accelerometer CSV ``Time, x, y, z`` (s since the script started,
  m/s^2 with gravity, ``None`` before the first event, ``\r`` line ends; ``.csv`` or ``.gz``, or a folder holding
  one) -> :func:`read_sensibility`
* ``sensorlog``: a SensorLog (iOS) CSV with ``accelerometerTimestamp_sinceReboot``, ``accelerometerAccelerationX``
  ... columns (g with iOS's sign, converted; gyroscope and magnetometer where logged; ``.csv`` or ``.gz``, or a folder
  holding one) -> :func:`read_sensorlog`
* ``matlab-mobile``: a MATLAB Mobile sensor log saved as a MAT-file (``timetable`` objects ``Acceleration``,
  ``AngularVelocity``, ``MagneticField``, ``Position`` where logged; ``.mat`` or ``.mat.gz``) -> :func:`read_matlabmobile`
* ``matlab-mobile-csv``: the CSV MATLAB writes from such a log's accelerometer timetable (``Acceleration_Timestamp,X,Y,Z``,
  datetime text; ``.csv`` or ``.gz``, or a folder holding one) -> :func:`read_matlabmobile_csv`
* ``pyshoe``: PyShoe processed trial, a MATLAB level-5 MAT-file (``.mat`` or ``.mat.gz``; read with numpy and
  zlib, :mod:`core.importers.matv5`) -> :func:`read_pyshoe`
* ``oxiod``: an OxIOD ``syn`` pair, the headerless ``imu<K>.csv`` (recognised by 16 numbers a line and Core Motion's
  unit gravity; the name must be ``imu<K>.csv``) with the Vicon truth ``vi<K>.csv`` beside it as ``posi``, or a
  folder holding one such pair -> :func:`read_oxiod`
* ``ridi``: a RIDI processed table, ``data.csv`` or an ``.xlsx`` of the same columns (``time``, ``acce_x/y/z``,
  ``gyro_x/y/z`` in its header), Tango truth as ``posi``, or a folder holding one -> :func:`read_ridi`
* ``tyrex``: a Tyrex attitude-benchmark walk, its folder ``datasets/android/<name>/`` (or ``datasets/ios/<name>/``) or one of its text files
  (``accelerometer.txt`` ...; recognised by the folder's files and the accelerometer's space-separated numbers),
  with its Qualisys truth ``datasets/qualisys/<name>.mat`` as ``posi`` -> :func:`read_tyrex`

The format is recognised by content (magic line, record tags, CSV headers,
binary record layout, archive members), never by the file name alone.  Every reader raises
:class:`core.recording.RecordingError` -- one line naming the file and, where
it applies, the line -- for input it cannot read, and finishes with
:func:`core.recording.repair_recording` (timestamps sorted, repeats dropped,
with a :class:`core.recording.TimestampRepairWarning`).  Every reader streams
its files (memory holds the recording, not the text), skips and counts a
few bad lines under one rule (:func:`core.recording.skip_bad_lines`), and
refuses a gzip stream or zip member larger than
:data:`core.recording.MAX_UNCOMPRESSED_BYTES` (``max_uncompressed_bytes=``).

Every importer's ``gps`` stream has the six columns of
:data:`core.recording.STREAM_SPECS` -- ``lat_deg, lon_deg, alt_m, hacc_m,
speed_m_s, course_deg`` (course clockwise from true north) -- with nan where
the app has no value or marks it invalid (one rule for all:
:func:`core.importers._common.gps_values`), and ``metadata["gps_check"]``
compares the reported speed and course with the fixes' own track.

Every recording carries ``metadata["source_format"]``, the app and its
version where known, ``metadata["time_base"]`` (what ``t_ns`` is), and when
absolute time is known ``metadata["unix_offset_ns"]`` (``unix_ns = t_ns +
unix_offset_ns``; survives slicing) and ``metadata["t0_unix_ns"]`` (Unix time
of the first event at import).  Streams besides ``acc``, ``gyro``, ``mag``,
``rotvec`` and ``gps``: ``posi`` (GetSensorData ground-truth landmarks),
``pressure`` (hPa), ``mag_uncal`` and ``gyro_uncal`` (Sensor Logger,
Microsoft/XYZ10), and ground truth that is part of a file format:
``waypoint`` (Microsoft/XYZ10 surveyor positions, floor-map metres), ``posi`` in metres (PyShoe's VICON
foot positions, ``east_m, north_m, up_m``; OxIOD's Vicon and RIDI's Tango positions, the same columns in the
room's or Tango's frame), ``zero_velocity`` (PyShoe's reference still/moving labels),
``wheel`` (trundle-wheel distance) and ``step_counts`` (cumulative step
counts of other counters logged in the file: the TrundleWheel phone's, the
Oxford validation files' app, ground-truth device and hardware counter);
see :data:`core.importers._common.EXTRA_STREAM_SPECS`.  Ground truth kept
in separate annotation files beside a recording (Oxford foot switches, Brajdic & Harle step
counts, IPOL foot strikes) is added by :func:`load_recording` as a ``step_counts`` stream
(:mod:`core.importers.beside`, which the benchmark readers use too).

Several IMUs in one recording (an IPOL trial: lower back and both feet) follow
:mod:`core.foot.devices`: the primary device's plain stream names, the others'
``acc@left_foot``, ``gyro@right_foot``, ..., described in ``metadata["devices"]``.
Where a format says where an IMU was worn (PyShoe: the foot; IPOL: lower back
and feet), ``device["placement"]`` says so and ``pdr replay`` picks its mode by it.
"""

from __future__ import annotations

import os
import zipfile

from core.recording import MAGIC, MAX_UNCOMPRESSED_BYTES, Recording, RecordingError, read_recording
from core.importers import accelcsv as _acsv
from core.importers import sensibility as _sens
from core.importers import sensorlog as _slog
from core.importers import brajdic as _bh
from core.importers import matlabmobile as _mm
from core.importers import getsensordata as _gsd
from core.importers import msindoor as _ms
from core.importers import oxford as _ox
from core.importers import oxiod as _oxi
from core.importers import phyphox as _phy
from core.importers import physicstoolbox as _ptb
from core.importers import sensorlogger as _sl
from core.importers import pyshoe as _ps
from core.importers import ridi as _ridi
from core.importers import trundle as _tw
from core.importers import tyrex as _tyrex
from core.importers import xio as _xio
from core.importers import xsens as _xs
from core.importers.matv5 import looks_like as _looks_like_mat
from core.importers._common import FileSet, head_bytes
from core.importers.beside import attach_truth_beside
from core.importers.accelcsv import read_accelcsv
from core.importers.sensibility import read_sensibility
from core.importers.sensorlog import read_sensorlog
from core.importers.brajdic import read_brajdic
from core.importers.matlabmobile import read_matlabmobile, read_matlabmobile_csv
from core.importers.getsensordata import read_getsensordata
from core.importers.msindoor import read_msindoor
from core.importers.oxford import read_oxford
from core.importers.phyphox import read_phyphox
from core.importers.physicstoolbox import read_physicstoolbox
from core.importers.sensorlogger import read_sensorlogger
from core.importers.pyshoe import read_pyshoe
from core.importers.trundle import read_trundle
from core.importers.oxiod import read_oxiod
from core.importers.ridi import read_ridi
from core.importers.tyrex import read_tyrex
from core.importers.xio import read_xio
from core.importers.xsens import read_xsens

PDR_RECORDING = "pdr-recording"
GETSENSORDATA = _gsd.FORMAT
SENSORLOGGER = _sl.FORMAT
PHYPHOX = _phy.FORMAT
MSINDOOR = _ms.FORMAT
BRAJDIC = _bh.FORMAT
OXFORD = _ox.FORMAT
TRUNDLE = _tw.FORMAT
XIO = _xio.FORMAT
XSENS = _xs.FORMAT
PYSHOE = _ps.FORMAT
PHYSICS_TOOLBOX = _ptb.FORMAT
ACCEL_CSV = _acsv.FORMAT
SENSIBILITY = _sens.FORMAT
SENSORLOG = _slog.FORMAT
MATLAB_MOBILE = _mm.FORMAT
MATLAB_MOBILE_CSV = _mm.CSV_FORMAT
OXIOD = _oxi.FORMAT
RIDI = _ridi.FORMAT
TYREX = _tyrex.FORMAT

#: format name -> what it is (for messages and the CLI's help)
FORMATS = {
    PDR_RECORDING: "this project's recording file (.txt/.gz starting '# pdr-recording')",
    GETSENSORDATA: "GetSensorData / IPIN logfile (ACCE;... GYRO;... lines, .txt or .gz)",
    SENSORLOGGER: "Sensor Logger export (zip or folder of Accelerometer.csv, Gyroscope.csv, ... with "
                  "'time,seconds_elapsed' headers)",
    PHYPHOX: "phyphox CSV export (zip or folder with 'Time (s)' CSVs and meta/, or one such CSV)",
    MSINDOOR: "Microsoft/XYZ10 Indoor Location Competition trace ('unix_ms<TAB>TYPE_ACCELEROMETER<TAB>...' lines "
              "after '#' header lines, .txt or .gz)",
    BRAJDIC: "Brajdic & Harle step-counting trace (21-byte big-endian records t_ns, type, x, y, z: .out; or "
             "'t_ns type x y z' text lines: .dat; .gz allowed)",
    OXFORD: "Oxford step-counter accelerometer file (headerless 't_ns,accuracy,ax,ay,az' or 7-field validation "
            "CSV, .csv or .gz, or the folder holding accelerometer.csv)",
    TRUNDLE: "TrundleWheel raw log or the authors' 1 Hz resampled file (';'-separated with 'time' and "
             "'m_accG_x/y/z' columns, .csv or .gz)",
    XIO: "x-io NGIMU sensors.csv (or its session folder) or x-IMU CSV ('Time (s)' or 'Packet number', then "
         "'Gyroscope X (deg/s)', 'Accelerometer X (g)', ... columns; .csv or .gz)",
    XSENS: "XSens text export ('Acquisition frequency: 100 Hz', then 'PacketCounter Acc_X ...'; .txt or .gz); an "
           "IPOL trial's <trial>_lb file reads its _lf/_rf foot files too",
    PYSHOE: "PyShoe processed trial (MATLAB level-5 MAT-file with imu and ts, VICON gt; .mat or .mat.gz)",
    PHYSICS_TOOLBOX: "Physics Toolbox Sensor Suite g-Force Meter CSV ('time,gFx,gFy,gFz' header, g units; .csv "
                     "or .gz)",
    ACCEL_CSV: "accelerometer CSV with the header 'Timestamp,Milliseconds,X,Y,Z' (ms since the start, m/s^2 with "
               "gravity; .csv or .gz)",
    SENSIBILITY: "Sensibility Testbed accelerometer CSV ('Time, x, y, z' header, s since the script started, m/s^2 "
                 "with gravity; .csv or .gz)",
    SENSORLOG: "SensorLog (iOS) CSV ('accelerometerTimestamp_sinceReboot', 'accelerometerAccelerationX', ... columns, g; "
               ".csv or .gz)",
    MATLAB_MOBILE: "MATLAB Mobile sensor log saved as a MAT-file (timetables Acceleration, AngularVelocity, "
                   "MagneticField, Position; .mat or .mat.gz)",
    MATLAB_MOBILE_CSV: "MATLAB Mobile accelerometer timetable written to CSV by MATLAB ('Acceleration_Timestamp,X,Y,Z' "
                       "header, datetime text, m/s^2 with gravity; .csv or .gz)",
    OXIOD: "OxIOD syn pair: headerless imu<K>.csv (16 numbers a line, Core Motion; the name imu<K>.csv is needed) "
           "with its Vicon truth vi<K>.csv beside it (.csv or .gz), or a folder holding one pair",
    RIDI: "RIDI processed table: data.csv or an .xlsx of its columns ('time', 'acce_x/y/z', 'gyro_x/y/z', ... "
          "'pos_x/y/z' the Tango truth), or a folder holding one",
    TYREX: "Tyrex attitude-benchmark walk: its folder datasets/android/<name>/ (accelerometer.txt, "
           "gyroscope-calibrated.txt, timeAlignment.txt: 't x y z' lines) or datasets/ios/<name>/ (gyroscope.txt, "
           "description.txt, the accelerometer in g) or one of its files, with its Qualisys truth "
           "datasets/qualisys/<name>.mat",
}


_SHORT = {
    PDR_RECORDING: "pdr-recording (this project's file)",
    GETSENSORDATA: "getsensordata (GetSensorData/IPIN logfile)",
    SENSORLOGGER: "sensorlogger (Sensor Logger zip or folder)",
    PHYPHOX: "phyphox (phyphox CSV export)",
    MSINDOOR: "msindoor (Microsoft/XYZ10 indoor-location trace)",
    BRAJDIC: "brajdic-harle (Brajdic & Harle .out/.dat trace)",
    OXFORD: "oxford-step-counter (Oxford step-counter accelerometer CSV)",
    TRUNDLE: "trundlewheel (TrundleWheel raw or resampled log)",
    XIO: "x-io (NGIMU sensors.csv or x-IMU CSV)",
    XSENS: "xsens (XSens text export, IPOL trials)",
    PYSHOE: "pyshoe (PyShoe processed .mat trial)",
    PHYSICS_TOOLBOX: "physics-toolbox (Physics Toolbox g-Force Meter CSV)",
    ACCEL_CSV: "accel-csv (Timestamp,Milliseconds,X,Y,Z accelerometer CSV)",
    SENSIBILITY: "sensibility-testbed (Sensibility Testbed Time, x, y, z CSV)",
    SENSORLOG: "sensorlog (SensorLog iOS CSV)",
    MATLAB_MOBILE: "matlab-mobile (MATLAB Mobile sensor log .mat)",
    MATLAB_MOBILE_CSV: "matlab-mobile-csv (MATLAB Mobile accelerometer CSV, Acceleration_Timestamp,X,Y,Z)",
    OXIOD: "oxiod (OxIOD syn imu<K>.csv with vi<K>.csv)",
    RIDI: "ridi (RIDI data.csv or .xlsx)",
    TYREX: "tyrex (Tyrex attitude-benchmark walk folder with its Qualisys .mat)",
}


def _unknown(path: str, why: str) -> RecordingError:
    return RecordingError(f"unrecognised recording format ({why}); supported: {', '.join(_SHORT.values())}", path)


#: the text formats' tests of a file's head, in the order they are tried (the most specific first)
_TEXT_TESTS = [
    (lambda head: head.startswith(MAGIC), PDR_RECORDING),
    (_gsd.looks_like, GETSENSORDATA),
    (_ms.looks_like, MSINDOOR),
    (_xio.looks_like_csv, XIO),
    (_xs.looks_like, XSENS),
    (_sl.looks_like_csv, SENSORLOGGER),
    (_phy.looks_like_csv, PHYPHOX),
    (_tw.looks_like_csv, TRUNDLE),
    (_ptb.looks_like_csv, PHYSICS_TOOLBOX),
    (_acsv.looks_like_csv, ACCEL_CSV),
    (_mm.looks_like_csv, MATLAB_MOBILE_CSV),
    (_sens.looks_like_csv, SENSIBILITY),
    (_slog.looks_like_csv, SENSORLOG),
    (_ridi.looks_like_csv, RIDI),
    (_bh.looks_like_text, BRAJDIC),
    (_oxi.looks_like, OXIOD),
    (_ox.looks_like, OXFORD),
]


def _detect_text(head: str) -> str | None:
    return next((fmt for test, fmt in _TEXT_TESTS if test(head)), None)


def _detect_fileset(fs: FileSet) -> str | None:
    names = fs.names()
    csvs = [n for n in names if n.lower().endswith(".csv")]
    if _phy.looks_like_meta(names):
        return PHYPHOX
    for n in csvs:
        if n.split("/")[-1].lower() == "metadata.csv" and _sl.looks_like_metadata(fs.head(n)):
            return SENSORLOGGER
    if _ox.looks_like_folder(fs):
        return OXFORD
    if _xio.looks_like_folder(fs):
        return XIO
    votes = {SENSORLOGGER: 0, PHYPHOX: 0}
    for n in csvs[:40]:
        head = fs.head(n, 2048)
        if _xio.looks_like_csv(head):
            continue  # x-io CSVs beside each other are recordings, not one export ("Time (s)" is phyphox's too)
        if _sl.looks_like_csv(head):
            votes[SENSORLOGGER] += 1
        elif _phy.looks_like_csv(head):
            votes[PHYPHOX] += 1
    if votes[SENSORLOGGER] or votes[PHYPHOX]:
        return max(votes, key=votes.get)
    if _ptb.csv_files(fs):
        return PHYSICS_TOOLBOX
    if _acsv.csv_files(fs):
        return ACCEL_CSV
    if _mm.csv_files(fs):
        return MATLAB_MOBILE_CSV
    if _sens.csv_files(fs):
        return SENSIBILITY
    if _slog.csv_files(fs):
        return SENSORLOG
    return None


def _single_mat(path: str) -> str | None:
    """The one MAT-file (``.mat`` or ``.mat.gz``) of a folder holding nothing else but text notes, else None."""
    if not os.path.isdir(path):
        return None
    files = [n for n in os.listdir(path) if os.path.isfile(os.path.join(path, n))]
    mats = [n for n in files if n.lower().endswith((".mat", ".mat.gz"))]
    others = [n for n in files if n not in mats and not n.lower().endswith((".md", ".txt", ".tsv"))]
    return os.path.join(path, mats[0]) if len(mats) == 1 and not others else None


def _folder_file(path: str) -> str | None:
    """The one OxIOD ``imu<K>.csv`` or RIDI table at the top of a folder (read through it), None without one;
    several are a :class:`RecordingError` naming them (replay one; ``pdr replay`` given the folder replays each)."""
    if not os.path.isdir(path):
        return None
    files = _oxi.imu_files(path) + _ridi.folder_files(path)
    if len(files) > 1:
        names = ", ".join(os.path.basename(f) for f in files[:8]) + (", ..." if len(files) > 8 else "")
        raise RecordingError(f"{len(files)} OxIOD/RIDI recordings in this folder ({names}): replay one file", path)
    return files[0] if files else None


def _half_match(path: str, head: str) -> RecordingError | None:
    """A clear error for a file that looks like part of a format but is not readable as it, else None."""
    if _oxi.looks_like_vicon(head):
        imu = _oxi.imu_partner(path)
        if imu is not None:
            return RecordingError(f"the Vicon truth of the OxIOD sequence {os.path.basename(imu)} beside it: replay "
                                  "that file, which reads this one as its truth", path)
    missing = _ridi.half_match(_ridi.header_names(head))
    if missing:
        return RecordingError(f"a RIDI-like table without its column(s) {', '.join(missing)} (RIDI's data.csv has "
                              f"{', '.join(_ridi.DETECT)})", path)
    return None


def detect_format(path) -> str:
    """The format of ``path`` (file or folder), from its content; :class:`RecordingError` if unknown."""
    path = str(path)
    if not os.path.exists(path):
        raise RecordingError("cannot open: no such file or folder", path)
    path = _single_mat(path) or path
    if os.path.isdir(path):
        with FileSet(path) as fs:
            fmt = _detect_fileset(fs)
        if fmt is None:
            if _tyrex.looks_like_folder(path):
                return TYREX
            inner = _folder_file(path)
            if inner is not None:
                return detect_format(inner)
            raise _unknown(path, "a folder without Sensor Logger, phyphox, Oxford step-counter, NGIMU, OxIOD, "
                                 "RIDI or Tyrex files")
        return fmt
    try:
        head = head_bytes(path, 65536)
    except OSError as e:
        raise RecordingError(f"cannot open: {e.strerror or e}", path) from None
    if head[:4] in (b"PK\x03\x04", b"PK\x05\x06"):
        try:
            with zipfile.ZipFile(path) as z:
                workbook = _ridi.is_xlsx(z.namelist())
        except (zipfile.BadZipFile, OSError) as e:
            raise RecordingError(f"unreadable zip archive: {e}", path) from None
        if workbook:
            names = _ridi.xlsx_header(path)
            if _ridi.looks_like_header(names):
                return RIDI
            missing = _ridi.half_match(names)
            raise _unknown(path, f"an Excel workbook whose first row lacks RIDI's {', '.join(missing)}" if missing
                           else "an Excel workbook without RIDI's columns (time, acce_x, ...) in its first row")
        try:
            with FileSet(path) as fs:
                fmt = _detect_fileset(fs)
        except (zipfile.BadZipFile, OSError) as e:
            raise RecordingError(f"unreadable zip archive: {e}", path) from None
        if fmt is None:
            raise _unknown(path, "a zip archive without Sensor Logger, phyphox, Oxford step-counter or NGIMU CSV "
                                 "files")
        return fmt
    if _tyrex.walk_folder(path) is not None:
        return TYREX  # one of a Tyrex walk's files: the folder is the recording
    if not head.strip():
        raise _unknown(path, "empty file")
    walk = _tyrex.walk_of_truth(path, head)
    if walk is not None:
        raise RecordingError(f"the Qualisys truth of the Tyrex walk {os.path.basename(walk)}: replay its folder "
                             f"{walk}, which reads this file as its truth", path)
    if _bh.looks_like_binary(head):
        return BRAJDIC
    if _looks_like_mat(head):
        names = _ps.mat_names(path)
        if _ps.looks_like(names):
            return PYSHOE
        if _mm.looks_like(names):
            return MATLAB_MOBILE
        raise _unknown(path, "a MAT-file without PyShoe's imu and ts variables or MATLAB Mobile's sensor timetables")
    if b"\x00" in head[:1024]:
        raise _unknown(path, "binary data")
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff")
    fmt = _detect_text(text)
    if fmt is None:
        raise _half_match(path, text) or _unknown(path, "the content matches none of them")
    if fmt == OXIOD and not _oxi.is_imu_name(path):
        raise RecordingError("an OxIOD sensor file by its content, but not named imu<K>.csv: its Vicon truth "
                             "vi<K>.csv is found by that name (rename it, or keep the pair's names)", path)
    if fmt == XSENS:
        part = _xs.trial_primary(path)
        if part is not None:
            primary, foot = part
            raise RecordingError(f"a foot sensor of the IPOL trial whose lower-back file {os.path.basename(primary)} "
                                 f"is beside it: replay that file, which reads all three sensors (--mode foot "
                                 f"--foot-device {foot} for this foot)", path)
    return fmt


def load_recording(path, *, warn: bool = True, platform: str | None = None,
                   max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES, truth_beside: bool = True) -> Recording:
    """Read any supported recording (see :data:`FORMATS`) into a :class:`Recording` in :mod:`core`'s conventions.

    ``warn``: emit :class:`core.recording.TimestampRepairWarning` for repaired
    timestamps (the repair is always listed in ``rec.repairs``).
    ``platform``: "android" or "ios" for a Sensor Logger export without
    Metadata.csv (ignored by the other formats); without it the environment
    variable ``PDR_SENSORLOGGER_PLATFORM`` is used for such an export.
    ``max_uncompressed_bytes``: a gzip stream or zip member larger than
    this uncompressed is refused (:data:`core.recording.MAX_UNCOMPRESSED_BYTES`).
    Every reader streams the file: memory holds the recording, not the text.
    ``truth_beside``: add the ground truth a dataset keeps in an annotation file beside the recording
    (Oxford ``stepcounter.csv``, Brajdic & Harle ``groundtruth_SC.txt``, IPOL ``<trial>.json``) as a
    ``step_counts`` stream (:mod:`core.importers.beside`).
    """
    path = str(path)
    limit = max_uncompressed_bytes
    fmt = detect_format(path)
    path = _single_mat(path) or path  # a folder holding one MAT-file is read through it
    if fmt in (OXIOD, RIDI):
        path = _folder_file(path) or path  # and one holding one OxIOD pair or RIDI table through that
    if fmt == TYREX:
        return read_tyrex(_tyrex.walk_folder(path) or path, warn=warn, max_uncompressed_bytes=limit)
    if fmt == PDR_RECORDING:
        rec = read_recording(path, warn=warn, max_uncompressed_bytes=limit)  # gzip or not by content
        rec.metadata.setdefault("source_format", PDR_RECORDING)
        return rec
    if fmt == GETSENSORDATA:
        return read_getsensordata(path, warn=warn, max_uncompressed_bytes=limit)
    if fmt == SENSORLOGGER:
        return read_sensorlogger(path, platform=platform, warn=warn, max_uncompressed_bytes=limit)
    readers = {PHYPHOX: read_phyphox, MSINDOOR: read_msindoor, BRAJDIC: read_brajdic, OXFORD: read_oxford,
               TRUNDLE: read_trundle, XIO: read_xio, XSENS: read_xsens, PYSHOE: read_pyshoe,
               PHYSICS_TOOLBOX: read_physicstoolbox, ACCEL_CSV: read_accelcsv, SENSIBILITY: read_sensibility, SENSORLOG: read_sensorlog,
               MATLAB_MOBILE: read_matlabmobile, MATLAB_MOBILE_CSV: read_matlabmobile_csv, OXIOD: read_oxiod,
               RIDI: read_ridi}
    rec = readers[fmt](path, warn=warn, max_uncompressed_bytes=limit)
    return attach_truth_beside(path, rec) if truth_beside else rec


__all__ = ["FORMATS", "detect_format", "load_recording", "read_getsensordata", "read_sensorlogger",
           "read_phyphox", "read_msindoor", "read_brajdic", "read_oxford", "read_trundle", "read_xio", "read_xsens",
           "read_pyshoe", "read_physicstoolbox", "read_accelcsv", "read_sensibility", "read_sensorlog", "read_oxiod", "read_ridi", "read_tyrex", "read_matlabmobile", "read_matlabmobile_csv", "PDR_RECORDING", "GETSENSORDATA", "SENSORLOGGER", "PHYPHOX",
           "MSINDOOR", "BRAJDIC", "OXFORD", "TRUNDLE", "XIO", "XSENS", "PYSHOE", "PHYSICS_TOOLBOX",
           "ACCEL_CSV", "SENSIBILITY", "SENSORLOG", "MATLAB_MOBILE", "MATLAB_MOBILE_CSV", "OXIOD", "RIDI", "TYREX"]
