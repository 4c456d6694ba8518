"""Shared helpers of the importers: file access as streams of lines, size limits, time and attitude checks.

Nothing here knows a particular app's format; the format modules call these
helpers and keep every unit, axis and sign conversion in their own code.
"""

from __future__ import annotations

import math
import os
import warnings
import zipfile
from contextlib import contextmanager

import numpy as np

from core import quaternion as quat
from core.conventions import ACC, STANDARD_GRAVITY_M_S2, wrap_angle
from core.geodesy import geodetic_to_enu
from core.recording import (
    GZIP_MAGIC, MAX_BAD_LINES, MAX_UNCOMPRESSED_BYTES, READ_ERRORS, ByteChunks, DamagedFileWarning, Recording,
    RecordingError, TextLines, acc_unit_guess, check_time_base, gunzip_partial, make_stream, over_limit_error,
    repair_recording, size_text,
)

ZIP_MAGIC = b"PK\x03\x04"
ZIP_EMPTY_MAGIC = b"PK\x05\x06"

#: extra stream names the importers may add besides those of :mod:`core.conventions`
POSI = "posi"  #: ground-truth landmarks (GetSensorData POSI lines)
#: ground-truth attitude of the device as a quaternion (w, x, y, z), device -> the truth's own frame (gravity-aligned,
#: z up, the same horizontal frame as its ``posi``; RIDI's Google Tango pose): the true heading of any device axis
TRUTH_ATTITUDE = "truth_attitude"
#: ground-truth attitude of a rigid body fixed to the device whose axes are not the device's (w, x, y, z, body -> the
#: truth's frame; OxIOD's Vicon marker body): the constant body-to-device rotation is unknown (to be fitted, e.g. from
#: the gyroscope: :func:`benchmarks.truth_walks.device_attitude`)
TRUTH_BODY_ATTITUDE = "truth_body_attitude"
PRESSURE = "pressure"  #: barometer, hPa (= mbar, as Android reports it)
MAG_UNCAL = "mag_uncal"  #: uncalibrated magnetometer, uT, device axes (hard iron not removed)
GYRO_UNCAL = "gyro_uncal"  #: uncalibrated gyroscope, rad/s, device axes (bias not removed)
WAYPOINT = "waypoint"  #: ground-truth positions in a map's East/North metres (Microsoft/XYZ10 TYPE_WAYPOINT)
WHEEL = "wheel"  #: ground-truth odometer: cumulative distance at each tick of a trundle wheel
STEP_COUNTS = "step_counts"  #: cumulative step counts logged with the recording, one column per counter
ZERO_VELOCITY = "zero_velocity"  #: reference zero-velocity labels (1 = foot still), one column per detector

EXTRA_STREAM_SPECS: dict[str, dict] = {
    PRESSURE: {"columns": ["p_hpa"], "unit": "hPa", "note": "barometric pressure (hPa = mbar, as Android reports it)"},
    MAG_UNCAL: {"columns": ["x", "y", "z"], "unit": "uT", "note": "magnetometer without the OS hard-iron correction"},
    GYRO_UNCAL: {"columns": ["x", "y", "z"], "unit": "rad/s", "note": "gyroscope without the OS bias correction"},
    WAYPOINT: {"columns": ["east_m", "north_m"], "unit": "m,m",
               "note": "ground-truth position the surveyor marked (TYPE_WAYPOINT), metres East and North in the "
                       "floor map's frame"},
    WHEEL: {"columns": ["distance_m"], "unit": "m",
            "note": "ground truth: trundle-wheel distance walked, cumulative, at each wheel tick"},
    STEP_COUNTS: {"columns": ["steps"], "unit": "1",
                  "note": "cumulative step counts logged with the recording (other counters than ours, or a "
                          "ground-truth device), one column per counter"},
    ZERO_VELOCITY: {"columns": ["still"], "unit": "1",
                    "note": "reference zero-velocity labels shipped with a foot-IMU recording (1 = the foot is "
                            "still, 0 = moving), one column per detector (PyShoe's zv_*_opt)"},
}


# ---------------------------------------------------------------------------
# reading files: plain, gzip, inside a folder or a zip archive -- as streams of lines

#: largest side file read whole (Sensor Logger's Metadata.csv, phyphox's meta/*.csv: a few hundred bytes)
MAX_SIDE_FILE_BYTES = 1 << 20


class TextDecoder:
    """An importer's text, a chunk of whole lines at a time (see :class:`core.recording.TextLines`).

    UTF-8, or Latin-1 for a chunk that is not (units like 'µT' are the only
    non-ASCII); line ends ``\\r\\n`` and ``\\r`` become ``\\n``; a NUL in the
    first 4096 characters is binary data, not text (a :class:`RecordingError`).
    """

    def __init__(self, source: str):
        self.source = source
        self.seen = 0

    def __call__(self, data: bytes) -> str:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("latin-1")
        if self.seen < 4096:
            if "\x00" in text[:4096 - self.seen]:
                raise RecordingError("binary data where text was expected", self.source)
            self.seen += len(text)
        if "\r" in text:
            text = text.replace("\r\n", "\n").replace("\r", "\n")
        return text


def note_damage(text: TextLines, source: str, repairs: list[str]) -> None:
    """After reading ``text``: a gzip stream cut part-way keeps its complete lines (noted in ``repairs``).

    Nothing complete before the damage is a :class:`RecordingError`.  Noted once.
    """
    if text.problem is None or text.noted:
        return
    text.noted = True
    if not text.kept_bytes:
        raise RecordingError(f"corrupt gzip data: {text.problem}", source)
    repairs.append(f"{source}: {text.problem}; kept the {text.kept_bytes} bytes before the damage")


@contextmanager
def _lines_of(f, source: str, repairs: list[str], limit: int | None, inflated: bool = False,
              what: str = "the archive member"):
    with f:
        text = TextLines(ByteChunks(f, source, limit=limit, inflated=inflated, what=what), source,
                         TextDecoder(source), split_cr=True)
        yield text
        note_damage(text, source, repairs)


def open_binary(path: str):
    """The file opened for reading bytes; what cannot be opened is a :class:`RecordingError` naming it."""
    try:
        return open(path, "rb")
    except OSError as e:
        raise RecordingError(f"cannot open: {e.strerror or e}", path) from None


def open_text(path: str, repairs: list[str], limit: int | None = MAX_UNCOMPRESSED_BYTES):
    """``with open_text(path, repairs) as text:`` the lines of a file (gzip by content), streamed.

    A gzip stream cut part-way gives its complete lines and a line in
    ``repairs`` once the text has been read; one inflating beyond ``limit``
    bytes is refused while it is read.
    """
    return _lines_of(open_binary(path), path, repairs, limit)


def feed_lines(text, source: str, repairs: list[str], chunk, bad: list, tail) -> None:
    """Give a text's lines to ``chunk(first line number, lines)``, a chunk at a time, as the readers do.

    The reading stops once ``bad`` (the reader's list of bad lines) holds
    more than :data:`core.recording.MAX_BAD_LINES`: the file will be refused.
    After the whole text, damage of a gzip stream is noted in ``repairs``
    (:func:`note_damage`) and a last line without its newline goes to
    ``tail(line number, line)``: the reader decides whether it was cut off.
    """
    for first, lines in text:
        chunk(first, lines)
        if len(bad) > MAX_BAD_LINES:
            return
    note_damage(text, source, repairs)
    if text.tail:
        tail(text.tail_line, text.tail)


def _first_bytes(f, source: str, n: int) -> bytes:
    raw = b""
    for chunk in ByteChunks(f, source, limit=None, chunk=n):
        raw += chunk
        if len(raw) >= n:
            break
    return raw[:n]


def is_zip(path: str) -> bool:
    """True if the file starts like a zip archive."""
    with open(path, "rb") as f:
        return f.read(4) in (ZIP_MAGIC, ZIP_EMPTY_MAGIC)


def head_bytes(path: str, n: int = 65536) -> bytes:
    """The first ``n`` bytes of a file, decompressed when it is gzip (for format detection)."""
    with open(path, "rb") as f:
        try:
            return _first_bytes(f, path, n)
        except RecordingError:
            return b""


def head_lines(head: str, n: int = 20) -> list[str]:
    """The first ``n`` non-blank whole lines of a file's head (for format detection; a cut last piece is left out)."""
    pieces = head.split("\n")
    if len(pieces) > 1:
        pieces.pop()  # after the last newline: "" or a line the head may have cut
    return [ln for ln in pieces if ln.strip()][:n]


def maybe_gunzip(data: bytes, source: str, repairs: list[str] | None = None) -> bytes:
    """``data`` gunzipped when it is gzip (bytes in memory; the readers stream instead: :func:`open_text`)."""
    if data[:2] == GZIP_MAGIC:
        raw, problem = gunzip_partial(data)
        if problem is not None:
            if repairs is None or not raw:
                raise RecordingError(f"corrupt gzip data: {problem}", source)
            repairs.append(f"{source}: {problem}; kept the {len(raw)} bytes before the damage")
        return raw
    return data


class FileSet:
    """A folder or a zip archive of files, addressed by their path inside it ('/'-separated).

    ``name.csv.gz`` is served as ``name.csv`` (decompressed), so a folder whose
    large files were gzip-compressed reads like the original export.  Files
    are read as streams of lines (:meth:`text`); a zip member whose declared
    size, or a gzip stream whose output, exceeds ``limit`` bytes
    (:data:`core.recording.MAX_UNCOMPRESSED_BYTES`) is refused naming the
    archive, the member, its size and the limit.
    """

    def __init__(self, path: str, limit: int | None = MAX_UNCOMPRESSED_BYTES):
        self.path = str(path)
        self.limit = limit
        #: damage repaired while reading members (a gzip member cut part-way: its complete lines are kept)
        self.repairs: list[str] = []
        self._zip: zipfile.ZipFile | None = None
        self._real: dict[str, str] = {}
        if os.path.isdir(self.path):
            for root, _dirs, files in os.walk(self.path):
                for fn in files:
                    full = os.path.join(root, fn)
                    rel = os.path.relpath(full, self.path).replace(os.sep, "/")
                    self._add(rel, full)
        else:
            try:
                self._zip = zipfile.ZipFile(self.path)
                infos = self._zip.infolist()
            except (zipfile.BadZipFile, *READ_ERRORS, ValueError) as e:
                raise RecordingError(f"not a folder or a readable zip archive: {e}", self.path) from None
            for info in infos:
                if not info.is_dir():
                    self._add(info.filename, info.filename)

    def _add(self, rel: str, real: str) -> None:
        if rel.startswith("__MACOSX/") or rel.split("/")[-1].startswith("._"):
            return  # resource forks added by macOS zip tools
        name = rel[:-3] if rel.lower().endswith(".gz") else rel
        self._real.setdefault(name, real)

    def names(self) -> list[str]:
        return sorted(self._real)

    def where(self, name: str) -> str:
        """A path for messages: ``archive.zip/inner.csv`` or the real file."""
        real = self._real[name]
        return f"{self.path}/{real}" if self._zip is not None else real

    def _open(self, name: str):
        real = self._real[name]
        try:
            if self._zip is None:
                return open(real, "rb")
            info = self._zip.getinfo(real)
            if self.limit is not None and info.file_size > self.limit:
                raise over_limit_error(f"archive member {real!r}", self.limit, self.path, size=info.file_size)
            return self._zip.open(info)
        except READ_ERRORS as e:
            raise RecordingError(f"cannot read: {getattr(e, 'strerror', None) or e}", self.where(name)) from None

    def text(self, name: str):
        """``with fs.text(name) as text:`` the member's lines, streamed (see :func:`open_text`)."""
        return _lines_of(self._open(name), self.where(name), self.repairs, self.limit, inflated=self._zip is not None,
                         what=f"archive member {self._real[name]!r}")

    def read_text(self, name: str, max_bytes: int = MAX_SIDE_FILE_BYTES) -> str:
        """The whole text of a small side file (metadata); over ``max_bytes`` it is a :class:`RecordingError`."""
        lines, size = [], 0
        with self.text(name) as text:
            for _, chunk in text:
                lines += chunk
                size += sum(map(len, chunk))
                if size > max_bytes:
                    break
        if size + len(text.tail) > max_bytes:
            raise RecordingError(f"over {size_text(max_bytes)} of text: not the small metadata file it should be",
                                 self.where(name))
        return "\n".join(lines + [text.tail])

    def head(self, name: str, n: int = 4096) -> str:
        try:
            with self._open(name) as f:
                raw = _first_bytes(f, self.where(name), n)
        except (RecordingError, *READ_ERRORS):
            return ""
        return raw.decode("utf-8", errors="replace").lstrip("\ufeff")

    def close(self) -> None:
        if self._zip is not None:
            self._zip.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ---------------------------------------------------------------------------
# one-file CSV formats (an accelerometer CSV, alone or as the one such CSV of a folder or zip)


def single_csv_files(fs: FileSet, looks_like) -> list[str]:
    """The CSVs of a folder or zip (top level and one folder down) whose head ``looks_like(head)`` accepts."""
    return [n for n in fs.names() if n.lower().endswith(".csv") and n.count("/") <= 1 and looks_like(fs.head(n))]


def read_single_csv(path: str, looks_like, read_table, what: str, repairs: list[str],
                    limit: int | None = MAX_UNCOMPRESSED_BYTES):
    """``read_table(text, where, repairs)`` on one CSV file (plain or gzip), or on the one CSV of a folder or zip
    that ``looks_like`` accepts (none, or several, is a :class:`RecordingError` naming ``what``; no such path too)."""
    if not os.path.exists(path):
        raise RecordingError("cannot open: no such file or folder", path)
    if os.path.isdir(path) or is_zip(path):
        with FileSet(path, limit) as fs:
            names = single_csv_files(fs, looks_like)
            if len(names) != 1:
                raise RecordingError(f"{len(names)} {what}s in this folder or archive: replay one file" if names
                                     else f"no {what} in this folder or archive", path)
            with fs.text(names[0]) as text:
                out = read_table(text, fs.where(names[0]), repairs)
            repairs += fs.repairs
        return out
    with open_text(path, repairs, limit) as text:
        return read_table(text, path, repairs)


# ---------------------------------------------------------------------------
# times in seconds

#: largest time (s) that fits int64 nanoseconds with room to spare
MAX_TIME_S = 9.0e9


def first_bad_time(t_s: np.ndarray) -> int | None:
    """Index of the first time (s) that is not finite or does not fit int64 nanoseconds, or ``None``."""
    bad = ~np.isfinite(t_s)
    bad[~bad] = np.abs(t_s[~bad]) > MAX_TIME_S
    idx = np.flatnonzero(bad)
    return int(idx[0]) if len(idx) else None


def device_y_bearing_deg(mat_nb: np.ndarray) -> np.ndarray:
    """Compass bearing (deg, clockwise from North) of the horizontal projection of the device y axis."""
    return np.degrees(np.arctan2(mat_nb[..., 0, 1], mat_nb[..., 1, 1]))


def tilt_compensated_bearing_deg(acc_b: np.ndarray, mag_b: np.ndarray) -> np.ndarray:
    """Bearing (deg) of the device y axis from gravity and the magnetic field (both device frame).

    ``up = acc/|acc|`` (Android sign: at rest the accelerometer points up),
    ``east = mag x up``, ``north = up x east``; the bearing is
    ``atan2(east . y_b, north . y_b)`` -- the same as Android's
    ``getRotationMatrix`` + ``getOrientation`` azimuth.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        up = acc_b / np.linalg.norm(acc_b, axis=-1, keepdims=True)
        east = np.cross(mag_b, up)
        east = east / np.linalg.norm(east, axis=-1, keepdims=True)
        north = np.cross(up, east)
    return np.degrees(np.arctan2(east[..., 1], north[..., 1]))


def sample_at(t_src: np.ndarray, v_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Rows of ``v_src`` at times ``t_dst``: linear interpolation per column, clamped at the ends."""
    ts = (t_src - t_src[0]).astype(np.float64)
    td = (t_dst - t_src[0]).astype(np.float64)
    return np.stack([np.interp(td, ts, v_src[:, j]) for j in range(v_src.shape[1])], axis=-1)


def attitude_checks(t_q: np.ndarray, q: np.ndarray, t_acc: np.ndarray, acc: np.ndarray,
                    t_mag: np.ndarray | None = None, mag: np.ndarray | None = None,
                    max_samples: int = 5000) -> dict:
    """How well an ENU<-device quaternion stream agrees with the raw sensors.

    ``tilt_err_deg``: median angle between ``R(q) up_b`` and ENU up, over
    samples where ``|acc|`` is within 1 m/s^2 of g (the accelerometer then
    measures mostly gravity).  ``heading_diff_deg``: median absolute
    difference between the bearing of the device y axis from ``q`` and from
    the tilt-compensated magnetometer (``nan`` without a magnetometer).
    """
    out = {"tilt_err_deg": float("nan"), "heading_diff_deg": float("nan"), "n": 0}
    if len(t_q) < 2 or len(t_acc) < 2:
        return out
    step = max(1, len(t_q) // max_samples)
    tq = t_q[::step]
    qq = q[::step]
    a = sample_at(t_acc, acc, tq)
    na = np.linalg.norm(a, axis=1)
    calm = np.abs(na - STANDARD_GRAVITY_M_S2) < 1.0
    if calm.sum() < 10:
        return out
    m = quat.to_matrix_array(qq[calm])
    up_b = a[calm] / na[calm, None]
    up_n = np.einsum("nij,nj->ni", m, up_b)
    out["tilt_err_deg"] = float(np.median(np.degrees(np.arccos(np.clip(up_n[:, 2], -1.0, 1.0)))))
    out["n"] = int(calm.sum())
    if t_mag is not None and mag is not None and len(t_mag) >= 2:
        mg = sample_at(t_mag, mag, tq[calm])
        ok = np.linalg.norm(mg, axis=1) > 1.0
        if ok.sum() >= 10:
            d = np.degrees(wrap_angle(np.radians(device_y_bearing_deg(m[ok]) - tilt_compensated_bearing_deg(up_b[ok], mg[ok]))))
            out["heading_diff_deg"] = float(np.median(np.abs(d)))
    return out


def magnetic_dip_deg(t_acc, acc, t_mag, mag) -> float:
    """Median inclination (deg) of the field below the horizon, from gravity and the magnetometer.

    Positive means the field points down, as in the northern hemisphere; a
    sign error in the accelerometer or magnetometer axes flips it.
    """
    if t_acc is None or t_mag is None or len(t_acc) < 2 or len(t_mag) < 2:
        return float("nan")
    step = max(1, len(t_mag) // 5000)
    tm = t_mag[::step]
    mg = mag[::step]
    a = sample_at(t_acc, acc, tm)
    na = np.linalg.norm(a, axis=1)
    nm = np.linalg.norm(mg, axis=1)
    ok = (np.abs(na - STANDARD_GRAVITY_M_S2) < 1.0) & (nm > 1.0)
    if ok.sum() < 10:
        return float("nan")
    s = -np.einsum("ij,ij->i", a[ok], mg[ok]) / (na[ok] * nm[ok])
    return float(np.median(np.degrees(np.arcsin(np.clip(s, -1.0, 1.0)))))


# ---------------------------------------------------------------------------
# the end of every importer


def acceleration_in_m_s2(acc: np.ndarray, what: str, source: str, repairs: list[str],
                         notes: dict | None = None) -> np.ndarray:
    """Accelerometer values (gravity included) in m/s^2: values in g are converted, anything else is an error.

    The median ``|a|`` decides: about 1 means g (converted, noted in
    ``repairs``), about 9.8 means m/s^2.  A phone swinging in a hand adds
    the centripetal acceleration of the arm to gravity, which lifts the
    median well above g (15 m/s^2 on a real Android walk); such a median,
    up to 2.5 g, is accepted as m/s^2 when 90 % of the samples still exceed
    0.6 g -- linear acceleration without gravity keeps passing near zero --
    and ``notes["acc_unit_check"]`` says so.
    """
    norm = np.linalg.norm(acc, axis=1)
    m = float(np.median(norm))
    low = float(np.percentile(norm, 10))
    guess = acc_unit_guess(m, low)
    if guess == "g":
        repairs.append(f"{source}: acceleration median |a| = {m:.3f}: values are in g, converted to m/s^2")
        return acc * STANDARD_GRAVITY_M_S2
    g = STANDARD_GRAVITY_M_S2
    if guess == "m/s^2":
        if m >= 1.4 * g and notes is not None:
            notes["acc_unit_check"] = (f"median |a| = {m:.2f} m/s^2 ({m / g:.2f} g) with 90 % of the samples above "
                                       f"{low:.2f} m/s^2: gravity plus strong motion (a swinging phone), taken "
                                       "as m/s^2")
        return acc
    raise RecordingError(f"acceleration ({what}) has median magnitude {m:.3g}, neither about 9.8 m/s^2 nor "
                         "about 1 g: cannot establish its unit (is it linear acceleration without gravity?)",
                         source)


# ---------------------------------------------------------------------------
# GPS fixes


def gps_values(lat, lon, alt=None, hacc=None, speed=None, course=None) -> np.ndarray:
    """The six ``gps`` columns (lat_deg, lon_deg, alt_m, hacc_m, speed_m_s, course_deg) from an app's fields.

    A field the app does not have is ``None`` (all nan).  The phone APIs'
    markers of an unknown value become nan here, once for every importer:

    * ``hacc <= 0``: Android's ``getAccuracy()`` is 0 without
      ``hasAccuracy()``, iOS and Sensor Logger write -1;
    * a negative speed or course: iOS (CoreLocation) writes -1;
    * a course of exactly 0.0: Android's ``getBearing()`` returns 0.0 without
      ``hasBearing()``, and apps that log it unconditionally (GetSensorData,
      Sensor Logger on Android) leave no other trace of it -- on real files
      it comes with a speed near 0; a true course of exactly 0.0 is lost.

    A speed of exactly 0 is kept (a standing receiver reports it too).
    Courses are wrapped to [0, 360).
    """
    lat = np.asarray(lat, dtype=np.float64)
    n = len(lat)

    def col(v):
        return np.full(n, np.nan) if v is None else np.asarray(v, dtype=np.float64).reshape(n)

    hacc, speed, course = col(hacc), col(speed), col(course)
    with np.errstate(invalid="ignore"):
        hacc = np.where(hacc > 0, hacc, np.nan)
        speed = np.where(speed >= 0, speed, np.nan)
        course = np.where(course > 0, np.mod(course, 360.0), np.nan)
    return np.column_stack([lat, col(lon), col(alt), hacc, speed, course])


def gps_check(t_ns: np.ndarray, values: np.ndarray, baseline_s: float = 5.0, moving_m_s: float = 0.7) -> dict:
    """The reported speed and course against the fixes' own track (diagnostics: nothing is changed).

    The track is taken between each fix and the first one at least
    ``baseline_s`` later (over one second GPS noise dwarfs a walker's
    progress).  ``speed_median_m_s``: median reported speed;
    ``track_speed_median_m_s``: median speed along the track;
    ``course_vs_track_deg``: median angle between the reported course and
    the track's bearing where the track moves faster than ``moving_m_s``
    (a few degrees to 15 on real walks; about 180 would be a sign error);
    ``zero_speed_while_moving``: fixes reporting a speed of 0 there.
    """
    order = np.argsort(np.asarray(t_ns, dtype=np.int64), kind="stable")
    v = np.asarray(values, dtype=np.float64)[order]
    t = (np.asarray(t_ns, dtype=np.int64)[order] - int(np.min(t_ns))) * 1e-9 if len(v) else np.zeros(0)
    out = {"n": int(len(v)), "speed_median_m_s": math.nan, "track_speed_median_m_s": math.nan,
           "course_vs_track_deg": math.nan, "zero_speed_while_moving": 0}
    speed, course = v[:, 4], v[:, 5]
    if np.isfinite(speed).any():
        out["speed_median_m_s"] = float(np.nanmedian(speed))
    ok = np.isfinite(v[:, 0]) & np.isfinite(v[:, 1])
    if ok.sum() < 2:
        return out
    t, lat, lon, speed, course = t[ok], v[ok, 0], v[ok, 1], speed[ok], course[ok]
    j = np.searchsorted(t, t + baseline_s)
    i = np.flatnonzero(j < len(t))
    if not len(i):
        return out
    j = j[i]
    east, north = geodetic_to_enu(lat, lon, (float(lat[0]), float(lon[0])))
    de, dn = east[j] - east[i], north[j] - north[i]
    track_speed = np.hypot(de, dn) / (t[j] - t[i])
    out["track_speed_median_m_s"] = float(np.median(track_speed))
    moving = track_speed > moving_m_s
    out["zero_speed_while_moving"] = int(np.sum(moving & (speed[i] == 0.0)))
    use = moving & np.isfinite(course[i])
    if use.any():
        d = np.degrees(wrap_angle(np.radians(course[i][use] - np.degrees(np.arctan2(de[use], dn[use])))))
        out["course_vs_track_deg"] = float(np.median(np.abs(d)))
    return out


def acc_csv_recording(path: str, looks_like, read_values, what: str, meta: dict, *, warn: bool = True,
                      max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES,
                      from_first: bool = False) -> Recording:
    """An accelerometer-only CSV (plain or gzip, or the one such CSV of a folder or zip) whose ``read_values`` gives
    rows ``ms, X, Y, Z`` (m/s^2 with gravity, Android device axes; the median ``|a|`` checked): ``t_ns = ms * 1e6``,
    counted from the first row's with ``from_first``."""
    path = str(path)
    repairs: list[str] = []
    notes: dict = {}
    v = read_single_csv(path, looks_like, read_values, what, repairs, max_uncompressed_bytes)
    if not len(v):
        raise RecordingError("no accelerometer lines", path)
    t_ns = np.round((v[:, 0] - (v[0, 0] if from_first else 0.0)) * 1e6).astype(np.int64)
    acc = acceleration_in_m_s2(v[:, 1:4], "X/Y/Z", path, repairs, notes)
    meta = {**meta, "acc_from": "X, Y, Z (m/s^2, gravity included, Android device axes)", **notes}
    return acc_only_recording(path, t_ns, acc, meta, repairs, warn=warn)


def acc_only_recording(path: str, t_ns: np.ndarray, acc: np.ndarray, meta: dict, repairs: list[str], *,
                       warn: bool = True, device: dict | None = None) -> Recording:
    """The recording of an accelerometer-only file (one ``acc`` stream): its repairs warned, then :func:`finish`."""
    rec = Recording({ACC: make_stream(ACC, t_ns, acc)}, metadata=meta, repairs=repairs, source=path)
    if device:
        rec.device = device
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=3)
    return finish(rec, warn=warn)


def finish(rec: Recording, *, warn: bool = True, unix_offset_ns: int | None = None) -> Recording:
    """Drop empty streams, check there is data, repair timestamps (with a warning), make metadata JSON-safe.

    With ``unix_offset_ns`` (Unix time minus sensor-clock time) the metadata
    also gets ``t0_unix_ns``, the Unix time of the first event.
    """
    rec.streams = {k: s for k, s in rec.streams.items() if len(s)}
    if not rec.streams:
        raise RecordingError("no sensor events found", rec.source or None)
    for name, s in rec.streams.items():
        check_time_base(name, s.t_ns, rec.source)
    rec = repair_recording(rec, warn=warn)
    if unix_offset_ns is not None:
        rec.metadata["t0_unix_ns"] = rec.t0_ns + unix_offset_ns
    rec.metadata = json_safe(rec.metadata)  # nan is not valid JSON
    return rec


def json_safe(obj):
    """Metadata with non-finite floats replaced by ``None`` and numpy scalars by Python ones (valid JSON)."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
