"""Reader for Physics Toolbox Sensor Suite's g-Force Meter CSV (Vieyra Software's phone app).

Format
======
Text (here also gzip), ``,``-separated, a header line naming the columns, then
one accelerometer event a line::

    time,gFx,gFy,gFz,TgF
    0.003000,-0.7813,-0.5739,0.2406,0.999

Columns are found by name; ``time`` and ``gFx, gFy, gFz`` are required.

* ``time``: seconds since the recording started (ms resolution: a fast
  accelerometer gives several lines with one time; the repeats are repaired
  with a warning, :func:`core.recording.repair_recording`).  ``t_ns =
  round(time * 1e9)``; absolute time is unknown.
* ``gFx, gFy, gFz``: the app's "g-force" (the specific force over standard
  gravity): the accelerometer with gravity, in g, in the device axes (flat,
  screen up: ``gFz = +1``).  Converted to m/s^2 (``* 9.80665``): the ``acc``
  stream.  The median magnitude is checked to be about 1 (a
  :class:`core.recording.RecordingError` otherwise, as for the other readers:
  :func:`core.importers._common.acceleration_in_m_s2`).
* ``TgF`` (the magnitude) is not read.  The app's multi-sensor export adds
  other columns (``ax, ay, az``, ``wx, wy, wz``, ...); they are listed in
  ``metadata["unused_columns"]``, not read: no real file of that layout was
  checked.

A folder (or zip) holding one such CSV is read through it (a folder of several is refused: name the
file).

Checked on one real Android export (57 s of walking, about 350 distinct
times a second, median ``|gF|`` 1.0).  A line with a field that is not a
number, or fewer fields than the columns read, is a bad line: skipped and
counted, or, past 100 or 1 % of the lines, a :class:`RecordingError` naming
the first.

Streams: ``acc``.
"""

from __future__ import annotations

import numpy as np

from core.conventions import STANDARD_GRAVITY_M_S2
from core.recording import MAX_UNCOMPRESSED_BYTES, Recording, RecordingError, skip_bad_lines
from core.importers._common import (
    FileSet, acc_only_recording, acceleration_in_m_s2, read_single_csv, single_csv_files,
)
from core.importers._csv import Table

FORMAT = "physics-toolbox"

#: the columns read: the time (s) and the g-force (g)
REQUIRED = ["time", "gFx", "gFy", "gFz"]
#: columns known and deliberately not read
IGNORED = ["TgF"]


def _header(head: str) -> list[str]:
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip()
    return [n.strip().strip('"').strip() for n in first.split(",")]


def looks_like_csv(head: str) -> bool:
    """The file starts with a ``,``-separated header whose first column is ``time`` and that names ``gFx/gFy/gFz``."""
    names = _header(head)
    return bool(names) and names[0] == "time" and all(n in names for n in REQUIRED[1:])


def csv_files(fs: FileSet) -> list[str]:
    """The g-Force Meter CSVs of a folder or zip (top level and one folder down)."""
    return single_csv_files(fs, looks_like_csv)


def read_physicstoolbox(path: str, *, warn: bool = True,
                        max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a g-Force Meter CSV (plain or gzip) into a :class:`Recording` (see the module doc).

    The file is streamed a chunk of lines at a time; a gzip stream inflating
    to over ``max_uncompressed_bytes`` is refused while it is read.
    """
    path = str(path)
    repairs: list[str] = []
    notes: dict = {}
    table, out = read_single_csv(path, looks_like_csv, _read_table, "Physics Toolbox g-Force Meter CSV", repairs,
                                 max_uncompressed_bytes)
    v = out["v"]
    if not len(v):
        raise RecordingError("no accelerometer lines", path)
    t_ns = np.round(v[:, 0] * 1e9).astype(np.int64)
    gf = v[:, 1:4]
    # the app writes g: about 1 in magnitude (converted by the common unit check, which notes it in repairs)
    acc = acceleration_in_m_s2(gf, "gFx/gFy/gFz", path, [], notes)
    if acc is gf:  # a median near 9.8 would be m/s^2: not this app's g-force
        raise RecordingError(f"gFx/gFy/gFz have median magnitude {np.median(np.linalg.norm(gf, axis=1)):.3g}: "
                             "the g-Force Meter writes g (about 1)", path)
    used = {h.lower() for h in REQUIRED + IGNORED}
    meta = {
        "source_format": FORMAT,
        "app": "Physics Toolbox Sensor Suite (g-Force Meter)",
        "time_base": "t_ns = the file's time (s since the recording started) * 1e9; absolute time unknown",
        "acc_from": f"gFx, gFy, gFz (g) * {STANDARD_GRAVITY_M_S2} m/s^2",
        "unused_columns": [h for h in table.header if h.lower() not in used],
        **notes,
    }
    return acc_only_recording(path, t_ns, acc, meta, repairs, warn=warn, device={"app": "Physics Toolbox Sensor Suite"})


def _read_table(text, where: str, repairs: list[str]) -> tuple[Table, dict]:
    with np.errstate(all="ignore"):
        table = Table(text, where, ",")
        if table.blank:
            raise RecordingError("empty file", where)
        idx = table.require(REQUIRED, "Physics Toolbox g-Force Meter CSV")
        out = table.read([(i, "f") for i in idx])
    skip_bad_lines(table.bad, table.n_lines, where, repairs)
    if table.dropped_tail is not None:
        repairs.append(f"{where}: dropped an incomplete last line {table.dropped_tail} (no newline: the file was cut "
                       "off mid-write)")
    return table, out
