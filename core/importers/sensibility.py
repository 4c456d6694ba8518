"""Reader for a Sensibility Testbed accelerometer CSV ``Time, x, y, z`` (the pedometer experiments of GitHub
``yh570/sensibility_testbed``, 2016).

Format
======
Text (here also gzip), ``,``-separated, lines ended by ``\\r`` (an old Mac export; ``\\n`` and ``\\r\\n`` are read
too).  The header's first four fields are ``Time, x, y, z`` (spaces around names allowed); further columns, when
present, are the experimenter's notes (lap times, "Total", the carry position) and are not read::

    Time, x, y, z,,,,,
    5.182108879,None,None,None,,Lap1,Lap2,Lap3
    5.341329813,-2.1955261,-9.421661,-0.33512878,,,,

* ``Time``: seconds since the logging script started (the testbed's ``getruntime()``); ``t_ns = Time * 1e9``.
  Absolute time is unknown.
* ``x, y, z``: the accelerometer with gravity, in m/s^2, Android device axes.  The median magnitude is checked
  (:func:`core.importers._common.acceleration_in_m_s2`: about 9.8 is m/s^2, about 1 is g and converted with a
  repair note, anything else -- linear acceleration -- is a :class:`core.recording.RecordingError`).
* ``None`` in ``x, y, z``: the script polled before the sensor's first event (the first 1-60 lines): such a
  line holds no sample and is dropped, counted in ``metadata["lines_without_sample"]``.  A line with some of
  ``x, y, z`` and not all is a bad line.

The script polls the sensor: a value repeated on consecutive lines is the sensor's last event read again
(2-9 % of the lines at 50-150 Hz on the 2016 phone); it is kept, as the file has it.

A folder (or zip) holding one such CSV is read through it (a folder of several is refused: name the file).
Checked on the thirteen counted clips copied from ``yh570/sensibility_testbed`` (``experiment_data/*/..._result.csv``;
50-155 Hz, median ``|a|`` 9.4-10.1 m/s^2).  A line with a field that is not a number, or fewer fields than the
columns read, is a bad line: skipped and counted, or, past 100 or 1 % of the lines, a :class:`RecordingError`
naming the first.

Streams: ``acc``.
"""

from __future__ import annotations

import numpy as np

from core.recording import MAX_UNCOMPRESSED_BYTES, Recording, RecordingError, skip_bad_lines
from core.importers._common import (
    FileSet, acc_only_recording, acceleration_in_m_s2, read_single_csv, single_csv_files,
)
from core.importers._csv import Table

FORMAT = "sensibility-testbed"

#: the header's first four fields (the rest are notes, not read)
HEADER = ["Time", "x", "y", "z"]
WHAT = "Sensibility Testbed accelerometer CSV (Time, x, y, z)"
#: what the script writes for an axis before the sensor's first event
NO_SAMPLE = "None"


def looks_like_csv(head: str) -> bool:
    """The first line's first four fields are ``Time, x, y, z`` (lines may end with ``\\r``)."""
    first = head.lstrip("\ufeff").replace("\r", "\n").split("\n", 1)[0]
    names = [n.strip().strip('"').strip() for n in first.split(",")]
    return names[:4] == HEADER


def csv_files(fs: FileSet) -> list[str]:
    """The Sensibility Testbed CSVs in a folder or zip (top level and one folder down)."""
    return single_csv_files(fs, looks_like_csv)


class _NoneAsEmpty:
    """The lines of a text with the script's ``None`` fields made empty (optional fields: nan)."""

    def __init__(self, text):
        self._text = text

    def __iter__(self):
        for first_no, lines in self._text:
            yield first_no, [_blank_none(ln) for ln in lines]

    @property
    def tail(self) -> str:
        return _blank_none(self._text.tail)

    @property
    def tail_line(self) -> int:
        return self._text.tail_line


def _blank_none(line: str) -> str:
    return line.replace(NO_SAMPLE, "") if NO_SAMPLE in line else line


def read_sensibility(path: str, *, warn: bool = True,
                     max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a Sensibility Testbed ``Time, x, y, z`` CSV (plain or gzip, or the one such CSV of a folder or zip)."""
    path = str(path)
    repairs: list[str] = []
    notes: dict = {}
    v = read_single_csv(path, looks_like_csv, _read_values, WHAT, repairs, max_uncompressed_bytes)
    none = np.isnan(v[:, 1:4])
    partial = none.any(axis=1) & ~none.all(axis=1)
    if partial.any():
        raise RecordingError(f"{int(partial.sum())} line(s) with some of x, y, z and not all", path)
    keep = ~none.any(axis=1)
    v = v[keep]
    if not len(v):
        raise RecordingError("no accelerometer samples (every x, y, z is None or empty)", path)
    t_ns = np.round(v[:, 0] * 1e9).astype(np.int64)
    acc = acceleration_in_m_s2(v[:, 1:4], "x/y/z", path, repairs, notes)
    meta = {
        "source_format": FORMAT,
        "app": "Sensibility Testbed logging script (an Android phone; the source names no model)",
        "time_base": "t_ns = the file's Time (s since the logging script started) * 1e9: absolute time unknown",
        "acc_from": "x, y, z (m/s^2, gravity included, Android device axes)",
        "lines_without_sample": int((~keep).sum()),
        **notes,
    }
    return acc_only_recording(path, t_ns, acc, meta, repairs, warn=warn)


def _read_values(text, where: str, repairs: list[str]) -> np.ndarray:
    with np.errstate(all="ignore"):
        table = Table(_NoneAsEmpty(text), where, ",")
        if table.blank:
            raise RecordingError("empty file", where)
        if table.header[:4] != HEADER:
            raise RecordingError(f"{WHAT}: the header must start 'Time, x, y, z' (header: "
                                 f"{','.join(table.header[:6])})", where, 1)
        out = table.read([(0, "f"), (1, "o"), (2, "o"), (3, "o")])
    skip_bad_lines(table.bad, table.n_lines, where, repairs)
    if table.dropped_tail is not None:
        repairs.append(f"{where}: dropped an incomplete last line {table.dropped_tail} (no newline: the file was cut "
                       "off mid-write)")
    return out["v"]
