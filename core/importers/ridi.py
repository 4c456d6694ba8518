"""Reader for a RIDI sequence (Yan, Shan & Furukawa, "RIDI: Robust IMU Double Integration", ECCV 2018): RIDI's
processed table, as its ``processed/data.csv`` or as an Excel sheet (``.xlsx``) holding the same columns.

Format
======
One row per sample, a header naming the columns (a first unnamed column is pandas' row index and is ignored).
The columns read (RIDI's names; other columns, e.g. ``linacce_*``, ``grav_*``, ``rv_*`` or a copy's added
``Estimated X`` / ``Distance Error``, are not)::

    time                       s, the Android sensor clock (``SensorEvent.timestamp`` / 1e9)
    acce_x, acce_y, acce_z     m/s^2, Android TYPE_ACCELEROMETER (gravity included), device axes
    gyro_x, gyro_y, gyro_z     rad/s, Android TYPE_GYROSCOPE, device axes
    magnet_x, magnet_y, magnet_z   uT, Android TYPE_MAGNETIC_FIELD (optional)
    pos_x, pos_y, pos_z        m, the Google Tango device's position (the truth; optional)
    ori_w, ori_x, ori_y, ori_z the Tango pose's orientation, device -> Tango frame (the truth; optional)

The values are Android's, in this project's units and axes already: kept as they are, ``t_ns = round(time *
1e9)`` (``time`` in nanoseconds, as RIDI's own ``processed/data.csv`` has it, is told by its step:
:func:`time_unit_s`); the acceleration passes the importers' unit check
(:func:`core.importers._common.acceleration_in_m_s2`: about 9.8 is m/s^2, about 1 is g and converted).  The Tango frame is gravity-aligned with z up; its x and y are a horizontal pair in the frame Tango started
in (not geographic East and North): ``posi`` (``east_m, north_m, up_m``) is ``(pos_x, pos_y, pos_z)``, to be compared
through offsets and after a rotation.  ``truth_attitude`` (:data:`core.importers._common.TRUTH_ATTITUDE`, ``w, x, y,
z``) is ``(ori_w, ori_x, ori_y, ori_z)``: the same device's attitude in that frame, so the true heading of any device
axis is known in the frame of ``posi`` (issue #25: checked on the copies in ``/work/extra_data2``, its tilt agrees with
Android's ``grav_*`` within 1 deg (median) on the bag and leg walks; the true offset of a hand-held phone's top edge is
0 +- 8 deg).

The CSV is read as a stream (:class:`core.importers._csv.Table`): a field read that is not a number, or a line
without its time or acceleration fields, is a bad line; an empty or absent gyroscope, magnetometer or position field
is a gap; a last line without its newline is a row when it has the header's fields, else it was cut off mid-write
(dropped and said in ``repairs``).  The Excel form is read with the standard library (``zipfile`` and
``xml.etree``): the first worksheet, numbers (``<v>``) and text (inline ``<is><t>`` or shared strings); a cell that
is not a number is a gap.  In both, a row without a usable time or acceleration is a bad line (skipped and counted,
or, past what :func:`core.recording.bad_lines_tolerated` allows, a :class:`RecordingError`).

Streams: ``acc``, ``gyro``, ``mag``, ``posi`` and ``truth_attitude`` where present.

Detection (:func:`core.importers.detect_format`)
================================================
A CSV whose first line names ``time``, ``acce_x/y/z`` and ``gyro_x/y/z`` (:data:`DETECT`; in any order, other
columns allowed), or an ``.xlsx`` (a zip with ``xl/worksheets/sheet*.xml``) whose first worksheet's first row
does.  A header naming three or more of RIDI's sensor columns (``acce_x``, ``gyro_y``, ``pos_z``, ...) but missing
one of :data:`DETECT` is refused naming what is missing; another workbook is refused as such.  A folder holding
one such CSV or workbook at its top (RIDI's ``processed/`` folder) is read through it.
"""

from __future__ import annotations

import os
import re
import warnings
import zipfile
from array import array
from xml.etree import ElementTree

import numpy as np

from core.conventions import ACC, GYRO, MAG
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import (
    POSI, TRUTH_ATTITUDE, acceleration_in_m_s2, finish, first_bad_time, head_bytes, open_text,
)
from core.importers._csv import Table

FORMAT = "ridi"
#: stream -> its three columns (RIDI's names)
COLUMNS = {
    ACC: ("acce_x", "acce_y", "acce_z"),
    GYRO: ("gyro_x", "gyro_y", "gyro_z"),
    MAG: ("magnet_x", "magnet_y", "magnet_z"),
    POSI: ("pos_x", "pos_y", "pos_z"),
    TRUTH_ATTITUDE: ("ori_w", "ori_x", "ori_y", "ori_z"),
}
REQUIRED = ("time", *COLUMNS[ACC])
#: the columns detection requires (RIDI always logs the gyroscope; the reader itself needs only REQUIRED)
DETECT = (*REQUIRED, *COLUMNS[GYRO])
#: RIDI's own sensor column names (for a half-match's error)
RIDI_NAMES = frozenset(f"{s}_{a}" for s in ("acce", "gyro", "linacce", "grav", "magnet", "pos", "ori", "rv",
                                            "game_rv") for a in "xyzw")
POSI_COLUMNS = ["east_m", "north_m", "up_m"]
#: the columns read, in this order (``time``, then the streams' columns)
READ = ("time", *(n for names in COLUMNS.values() for n in names))
_NS = "{http://schemas.openxmlformats.org/spreadsheetml/2006/main}"
_CELL = re.compile(r"([A-Z]+)(\d+)$")


def _col_index(ref: str) -> int:
    """0-based column of a cell reference (``"AB12"`` -> 27)."""
    letters = _CELL.match(ref).group(1)
    n = 0
    for ch in letters:
        n = n * 26 + ord(ch) - 64
    return n - 1


def _sheet_rows(z: zipfile.ZipFile, path: str, limit: int | None):
    """The rows of the first worksheet of an open .xlsx, each a dict column -> float or str (streamed)."""
    names = z.namelist()
    sheets = sorted(n for n in names if n.startswith("xl/worksheets/sheet") and n.endswith(".xml"))
    if not sheets:
        raise RecordingError("an .xlsx without a worksheet", path)
    if limit is not None and z.getinfo(sheets[0]).file_size > limit:
        raise RecordingError(f"worksheet over {limit} bytes uncompressed: refused", path)
    shared: list[str] = []
    if "xl/sharedStrings.xml" in names:
        root = ElementTree.fromstring(z.read("xl/sharedStrings.xml"))
        shared = ["".join(t.text or "" for t in si.iter(_NS + "t")) for si in root.iter(_NS + "si")]
    with z.open(sheets[0]) as f:
        for _, el in ElementTree.iterparse(f):
            if el.tag != _NS + "row":
                continue
            cells: dict[int, object] = {}
            for c in el.iter(_NS + "c"):
                j = _col_index(c.get("r", "A1"))
                kind = c.get("t")
                v = c.find(_NS + "v")
                if kind == "inlineStr":
                    cells[j] = "".join(t.text or "" for t in c.iter(_NS + "t"))
                elif kind == "s" and v is not None:
                    cells[j] = shared[int(v.text)]
                elif v is not None and v.text is not None:
                    try:
                        cells[j] = float(v.text)
                    except ValueError:
                        cells[j] = v.text
            el.clear()
            yield cells


def _header_of(cells: dict) -> list[str]:
    return [str(cells.get(j, "")).strip() for j in range(max(cells) + 1 if cells else 0)]


def _open_xlsx(path: str) -> zipfile.ZipFile:
    try:
        return zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as e:
        raise RecordingError(f"not a readable .xlsx: {e}", path) from None


#: what a damaged workbook raises while it is read (turned into a RecordingError)
_XLSX_ERRORS = (ElementTree.ParseError, zipfile.BadZipFile, EOFError, OSError, KeyError, IndexError, ValueError,
                AttributeError)


def _xlsx_table(path: str, limit: int | None):
    """The columns :data:`READ` of the first worksheet of an .xlsx: ``(header, present, values, row numbers, [], n)``
    as :func:`_csv_table` (a cell that is not a number, or absent, is nan)."""
    header: list[str] = []
    where: list[int] = []
    flat = array("d")
    nan = float("nan")
    try:
        with _open_xlsx(path) as z:
            for cells in _sheet_rows(z, path, limit):
                if not header:
                    header = _header_of(cells)
                    if any(c not in header for c in REQUIRED):
                        break
                    where = [header.index(n) if n in header else -1 for n in READ]
                    continue
                flat.extend(x if isinstance(x, float) else nan for x in (cells.get(j) for j in where))
    except _XLSX_ERRORS as e:
        raise RecordingError(f"damaged .xlsx worksheet: {e}", path) from None
    _require(header, path)
    v = (np.frombuffer(flat, dtype=np.float64) if flat else np.zeros(0)).reshape(-1, len(READ))  # no copy
    return header, [n for n in READ if n in header], v, np.arange(len(v)) + 2, [], len(v)


def is_xlsx(names) -> bool:
    """A zip archive's member names are an Excel workbook's (a worksheet under ``xl/worksheets/``)."""
    return any(n.startswith("xl/worksheets/sheet") and n.endswith(".xml") for n in names)


def xlsx_header(path: str, limit: int | None = MAX_UNCOMPRESSED_BYTES) -> list[str]:
    """The first row of an .xlsx's first worksheet (read alone: the sheet is streamed and left after it)."""
    try:
        with _open_xlsx(path) as z:
            return next((_header_of(cells) for cells in _sheet_rows(z, path, limit)), [])
    except _XLSX_ERRORS as e:
        raise RecordingError(f"damaged .xlsx worksheet: {e}", path) from None


def header_names(head: str) -> list[str]:
    """The names of a CSV head's first line (``,``-separated, spaces and quotes stripped)."""
    first = head.lstrip("\ufeff").replace("\r", "\n").split("\n", 1)[0]
    return [n.strip().strip('"').strip() for n in first.split(",")]


def looks_like_header(names) -> bool:
    """The header names RIDI's ``time``, ``acce_x/y/z`` and ``gyro_x/y/z`` (see the module doc, *Detection*)."""
    return all(n in names for n in DETECT)


def half_match(names) -> list[str]:
    """The detection columns missing from a header that names at least three of RIDI's sensor columns but not
    all of :data:`DETECT` (for an error that says what is missing); ``[]`` otherwise."""
    ridi = [n for n in names if n in RIDI_NAMES]
    missing = [n for n in DETECT if n not in names]
    return missing if len(ridi) >= 3 and missing else []


def looks_like_csv(head: str) -> bool:
    """The first line of a CSV is RIDI's header (:func:`looks_like_header`)."""
    return looks_like_header(header_names(head))


def _file_matches(path: str) -> bool:
    try:
        if zipfile.is_zipfile(path):
            return looks_like_header(xlsx_header(path))
        return looks_like_csv(head_bytes(path, 65536).decode("utf-8", errors="replace"))
    except (RecordingError, *_XLSX_ERRORS):
        return False


def folder_files(folder: str) -> list[str]:
    """The RIDI tables (``.csv``, ``.csv.gz``, ``.xlsx``) at the top of ``folder`` (sorted by name)."""
    if not os.path.isdir(folder):
        return []
    names = sorted(n for n in os.listdir(folder) if n.lower().endswith((".csv", ".csv.gz", ".xlsx")))
    return [os.path.join(folder, n) for n in names
            if os.path.isfile(os.path.join(folder, n)) and _file_matches(os.path.join(folder, n))]


def _require(header: list[str], path: str) -> None:
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise RecordingError(f"not a RIDI table: no column {', '.join(missing)}", path)


def _csv_table(path: str, repairs: list[str], limit: int | None):
    """RIDI's ``data.csv`` read once as a stream (:class:`core.importers._csv.Table`): ``(header, present, values
    (n, len(READ)) with nan for the absent columns, file line numbers (n,), bad lines, data lines)``."""
    with open_text(path, repairs, limit) as text, np.errstate(all="ignore"):
        table = Table(text, path, ",")
        _require(table.header, path)
        present = [n for n in READ if n in table.header]
        out = table.read([(table.header.index(n), "f" if n in REQUIRED else "o") for n in present], with_lines=True)
    if table.dropped_tail is not None:
        repairs.append(f"{path}: dropped an incomplete last line {table.dropped_tail} (no newline: the file was cut "
                       "off mid-write)")
    v = np.full((len(out["v"]), len(READ)), np.nan)
    v[:, [READ.index(n) for n in present]] = out["v"]
    return table.header, present, v, out["line"], table.bad, table.n_lines


#: RIDI's ``processed/data.csv`` keeps the Android sensor clock in nanoseconds (its loaders divide by 1e9); the
#: ``.xlsx`` copies hold seconds.  A median step between samples above this many units is nanoseconds (a sensor
#: at 1 Hz to 10 kHz has a step of 1e-4 to 1 s, or 1e5 to 1e9 ns)
NANOSECOND_MIN_STEP = 1e3


def time_unit_s(t: np.ndarray) -> float:
    """Seconds per unit of a RIDI ``time`` column: 1e-9 when its median step says nanoseconds, else 1 (seconds)."""
    d = np.diff(t[np.isfinite(t)])
    d = d[d > 0]
    return 1e-9 if len(d) and float(np.median(d)) > NANOSECOND_MIN_STEP else 1.0


def read_ridi(path: str, *, warn: bool = True,
              max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a RIDI processed table (``data.csv``, or an ``.xlsx`` of the same columns; see the module doc)."""
    path = str(path)
    repairs: list[str] = []
    if zipfile.is_zipfile(path):
        header, present, v, line, bad, n_lines = _xlsx_table(path, max_uncompressed_bytes)
    else:
        header, present, v, line, bad, n_lines = _csv_table(path, repairs, max_uncompressed_bytes)
    if not len(v):
        raise RecordingError("no sensor events found", path)

    def block(names):
        return v[:, [READ.index(n) for n in names]] if all(n in present for n in names) else None

    unit_s = time_unit_s(v[:, 0])
    t = v[:, 0] * unit_s
    good = np.isfinite(t) & np.all(np.isfinite(block(COLUMNS[ACC])), axis=1)
    bad = sorted(bad + [RecordingError("no usable time or acceleration", path, int(line[i]))
                        for i in np.flatnonzero(~good)], key=lambda e: e.line)
    skip_bad_lines(bad, n_lines, path, repairs)
    v, t = v[good], t[good]
    j = first_bad_time(t)
    if j is not None:
        raise RecordingError(f"time value {j + 1} is not a usable time: {float(t[j])!r}", path)
    t_ns = np.round(t * 1e9).astype(np.int64)
    notes: dict = {}
    streams = {}
    for name, names in COLUMNS.items():
        vals = block(names)
        if vals is None:
            continue
        ok = np.all(np.isfinite(vals), axis=1)
        if name == POSI:
            streams[POSI] = make_stream(POSI, t_ns[ok], vals[ok], POSI_COLUMNS, "m,m,m",
                                        "ground truth: Google Tango position (pos_x, pos_y, pos_z), z up, x and y "
                                        "in Tango's start frame, not geographic")
        elif name == TRUTH_ATTITUDE:
            ok = ok & (np.abs(np.linalg.norm(np.where(np.isfinite(vals), vals, 0.0), axis=1) - 1.0) < 0.01)  # unit
            streams[name] = make_stream(name, t_ns[ok], vals[ok], ["w", "x", "y", "z"], "1",
                                        "ground truth: Google Tango orientation (ori_w, ori_x, ori_y, ori_z), device "
                                        "-> the frame of posi")
        elif name == ACC:
            streams[ACC] = make_stream(ACC, t_ns, acceleration_in_m_s2(vals, "acce_x/y/z", path, repairs, notes))
        else:
            streams[name] = make_stream(name, t_ns[ok], vals[ok])
    meta = {"source_format": FORMAT, "app": "RIDI (Android; Google Tango truth)",
            "time_base": ("t_ns = round(time * 1e9): RIDI's time in s (the Android sensor clock)" if unit_s == 1.0 else
                          "t_ns = time: RIDI's time in ns (the Android sensor clock, processed/data.csv)"),
            "columns_ignored": [h for h in header if h and h not in REQUIRED and
                                not any(h in c for c in COLUMNS.values())][:40], **notes}
    if warn and repairs:
        warnings.warn("; ".join(repairs), DamagedFileWarning, stacklevel=2)
    return finish(Recording(streams, device={"app": "RIDI", "platform": "android"}, metadata=meta, repairs=repairs,
                            source=path), warn=warn)
