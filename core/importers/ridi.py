"""Reader for a RIDI sequence (Yan, Shan & Furukawa, "RIDI: Robust IMU Double Integration", ECCV 2018): RIDI's
processed table, as its ``processed/data.csv`` or as an Excel sheet (``.xlsx``) holding the same columns.

Format
======
One row per sample, a header naming the columns (a first unnamed column is pandas' row index and is ignored).
The columns read (RIDI's names; other columns, e.g. ``linacce_*``, ``grav_*``, ``rv_*``, ``ori_*`` or a copy's
added ``Estimated X`` / ``Distance Error``, are not)::

    time                       s, the Android sensor clock (``SensorEvent.timestamp`` / 1e9)
    acce_x, acce_y, acce_z     m/s^2, Android TYPE_ACCELEROMETER (gravity included), device axes
    gyro_x, gyro_y, gyro_z     rad/s, Android TYPE_GYROSCOPE, device axes
    magnet_x, magnet_y, magnet_z   uT, Android TYPE_MAGNETIC_FIELD (optional)
    pos_x, pos_y, pos_z        m, the Google Tango device's position (the truth; optional)

The values are Android's, in this project's units and axes already: kept as they are, ``t_ns = round(time *
1e9)``.  The Tango frame is gravity-aligned with z up; its x and y are a horizontal pair in the frame Tango started
in (not geographic East and North): ``posi`` (``east_m, north_m, up_m``) is ``(pos_x, pos_y, pos_z)``, to be compared
through offsets and after a rotation.

The Excel form is read with the standard library (``zipfile`` and ``xml.etree``): the first worksheet, numbers
(``<v>``) and text (inline ``<is><t>`` or shared strings); a cell that is not a number is a gap.  A row without a
usable time or acceleration is a bad line (skipped and counted, or, past what
:func:`core.recording.bad_lines_tolerated` allows, a :class:`RecordingError`).

Streams: ``acc``, ``gyro``, ``mag`` and ``posi`` where present.
"""

from __future__ import annotations

import re
import warnings
import zipfile
from xml.etree import ElementTree

import numpy as np

from core.conventions import ACC, GYRO, MAG
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import POSI, finish, first_bad_time, open_text

FORMAT = "ridi"
#: stream -> its three columns (RIDI's names)
COLUMNS = {
    ACC: ("acce_x", "acce_y", "acce_z"),
    GYRO: ("gyro_x", "gyro_y", "gyro_z"),
    MAG: ("magnet_x", "magnet_y", "magnet_z"),
    POSI: ("pos_x", "pos_y", "pos_z"),
}
REQUIRED = ("time", *COLUMNS[ACC])
POSI_COLUMNS = ["east_m", "north_m", "up_m"]
_NS = "{http://schemas.openxmlformats.org/spreadsheetml/2006/main}"
_CELL = re.compile(r"([A-Z]+)(\d+)$")


def _col_index(ref: str) -> int:
    """0-based column of a cell reference (``"AB12"`` -> 27)."""
    letters = _CELL.match(ref).group(1)
    n = 0
    for ch in letters:
        n = n * 26 + ord(ch) - 64
    return n - 1


def _xlsx_rows(path: str, limit: int | None):
    """``(header, rows)`` of the first worksheet of an .xlsx: header strings, rows as lists (floats, nan gaps)."""
    try:
        z = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as e:
        raise RecordingError(f"not a readable .xlsx: {e}", path) from None
    with z:
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
        header: list[str] = []
        rows: list[list[float]] = []
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
                width = max(cells) + 1 if cells else 0
                if not header:
                    header = [str(cells.get(j, "")).strip() for j in range(width)]
                    continue
                rows.append([x if isinstance(x, float) else float("nan")
                             for x in (cells.get(j) for j in range(len(header)))])
    return header, rows


def _csv_rows(path: str, repairs: list[str], limit: int | None):
    """``(header, rows)`` of RIDI's ``data.csv`` (a field that is not a number is a gap)."""
    header: list[str] = []
    rows: list[list[float]] = []
    with open_text(path, repairs, limit) as text:
        for _, lines in text:
            for line in lines:
                if not line.strip():
                    continue
                parts = line.split(",")
                if not header:
                    header = [p.strip() for p in parts]
                    continue
                row = []
                for p in parts[:len(header)]:
                    try:
                        row.append(float(p))
                    except ValueError:
                        row.append(float("nan"))
                rows.append(row + [float("nan")] * (len(header) - len(row)))
    return header, rows


def read_ridi(path: str, *, warn: bool = True,
              max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a RIDI processed table (``data.csv``, or an ``.xlsx`` of the same columns; see the module doc)."""
    path = str(path)
    repairs: list[str] = []
    if zipfile.is_zipfile(path):
        header, rows = _xlsx_rows(path, max_uncompressed_bytes)
    else:
        header, rows = _csv_rows(path, repairs, max_uncompressed_bytes)
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise RecordingError(f"not a RIDI table: no column {', '.join(missing)}", path)
    if not rows:
        raise RecordingError("no sensor events found", path)
    v = np.asarray(rows, dtype=np.float64)
    col = {name: header.index(name) for name in header if name}

    def block(names):
        return v[:, [col[n] for n in names]] if all(n in col for n in names) else None

    t = v[:, col["time"]]
    acc = block(COLUMNS[ACC])
    good = np.isfinite(t) & np.all(np.isfinite(acc), axis=1)
    bad = [RecordingError("no usable time or acceleration", path, int(i) + 2) for i in np.flatnonzero(~good)]
    skip_bad_lines(bad, len(v), path, repairs)
    v, t = v[good], t[good]
    j = first_bad_time(t)
    if j is not None:
        raise RecordingError(f"time value {j + 1} is not a usable time: {float(t[j])!r}", path)
    t_ns = np.round(t * 1e9).astype(np.int64)
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
        else:
            streams[name] = make_stream(name, t_ns[ok], vals[ok])
    meta = {"source_format": FORMAT, "app": "RIDI (Android; Google Tango truth)",
            "time_base": "t_ns = round(time * 1e9): RIDI's time (s, the Android sensor clock)",
            "columns_ignored": [h for h in header if h and h not in REQUIRED and
                                not any(h in c for c in COLUMNS.values())][:40]}
    if warn and repairs:
        warnings.warn("; ".join(repairs), DamagedFileWarning, stacklevel=2)
    return finish(Recording(streams, device={"app": "RIDI", "platform": "android"}, metadata=meta, repairs=repairs,
                            source=path), warn=warn)
