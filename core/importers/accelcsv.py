"""Reader for a plain accelerometer CSV ``Timestamp,Milliseconds,X,Y,Z`` (an Android logger the source does not name).

Format
======
Text (here also gzip), ``,``-separated, the header line exactly
``Timestamp,Milliseconds,X,Y,Z``, then one accelerometer event a line::

    Timestamp,Milliseconds,X,Y,Z
    2022-05-19 23:33:19,10,-0.39111328,4.5970917,9.088684

* ``Timestamp``: the wall clock to the whole second (local time, time zone
  not stated): not read -- absolute time is unknown.
* ``Milliseconds``: milliseconds since the recording started; ``t_ns =
  Milliseconds * 1e6`` (a repeated or backward millisecond is repaired with
  a warning, :func:`core.recording.repair_recording`).
* ``X, Y, Z``: the accelerometer with gravity, in m/s^2, Android device axes
  (flat, screen up: ``Z = +9.8``).  The median magnitude is checked
  (:func:`core.importers._common.acceleration_in_m_s2`: about 9.8 is m/s^2,
  about 1 is g and converted with a repair note, anything else -- linear
  acceleration without gravity -- is a :class:`core.recording.RecordingError`).

A folder (or zip) holding one such CSV is read through it (a folder of several is refused: name the file).

Checked on the twelve 20-step clips of GitHub ``sgrzegorz/StepApp`` (``data/20steps``; 100 Hz, 15-19 s, median
``|a|`` 9.9-10.1 m/s^2).  A line with a field that is not a number, or fewer fields than the columns read, is a
bad line: skipped and counted, or, past 100 or 1 % of the lines, a :class:`RecordingError` naming the first.

Streams: ``acc``.
"""

from __future__ import annotations

import numpy as np

from core.recording import MAX_UNCOMPRESSED_BYTES, Recording, RecordingError, skip_bad_lines
from core.importers._common import FileSet, acc_csv_recording, single_csv_files
from core.importers._csv import Table

FORMAT = "accel-csv"

#: the header, column for column
HEADER = ["Timestamp", "Milliseconds", "X", "Y", "Z"]
#: the columns read: the time (ms since the start) and the accelerometer (m/s^2)
READ = ["Milliseconds", "X", "Y", "Z"]
WHAT = "accelerometer CSV (Timestamp,Milliseconds,X,Y,Z)"


def looks_like_csv(head: str) -> bool:
    """The file's first line is the header ``Timestamp,Milliseconds,X,Y,Z`` (spaces and quotes around names allowed)."""
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip()
    return [n.strip().strip('"').strip() for n in first.split(",")] == HEADER


def csv_files(fs: FileSet) -> list[str]:
    """The accelerometer CSVs of this layout in a folder or zip (top level and one folder down)."""
    return single_csv_files(fs, looks_like_csv)


def read_accelcsv(path: str, *, warn: bool = True,
                  max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a ``Timestamp,Milliseconds,X,Y,Z`` CSV (plain or gzip, or the one such CSV of a folder or zip)."""
    meta = {
        "source_format": FORMAT,
        "app": "not named by the source (an Android accelerometer logger)",
        "time_base": "t_ns = the file's Milliseconds (ms since the recording started) * 1e6; the Timestamp column "
                     "(wall clock, whole seconds, time zone not stated) is not read: absolute time unknown",
    }
    return acc_csv_recording(path, looks_like_csv, _read_values, WHAT, meta, warn=warn,
                             max_uncompressed_bytes=max_uncompressed_bytes)


def _read_values(text, where: str, repairs: list[str]) -> np.ndarray:
    with np.errstate(all="ignore"):
        table = Table(text, where, ",")
        if table.blank:
            raise RecordingError("empty file", where)
        idx = table.require(READ, WHAT)
        out = table.read([(i, "f") for i in idx])
    skip_bad_lines(table.bad, table.n_lines, where, repairs)
    if table.dropped_tail is not None:
        repairs.append(f"{where}: dropped an incomplete last line {table.dropped_tail} (no newline: the file was cut "
                       "off mid-write)")
    return out["v"]
