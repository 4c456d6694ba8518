"""Reader for the Oxford step-counter dataset's accelerometer files (Oxford-step-counter/DataSet).

Format
======
Headerless CSV (here also gzip), one accelerometer event a line, in one of
the dataset's two layouts, told apart by the number of fields:

``optimisation/data/<Phone>_<User>_<Surface>_<Placement>_<n>/accelerometer.csv``, 5 fields::

    t_ns,accuracy,ax,ay,az
    263239144953734,2,1.9400482,5.161789,10.162003

``validation/*.csv``, 7 fields::

    t_ns,ax,ay,az,steps_app_algorithm,steps_ground_truth_device,steps_android_hw_counter

``t_ns`` is Android's ``SensorEvent.timestamp`` (integer nanoseconds since
boot); ``accuracy`` the sensor's accuracy flag (counted in
``metadata["accuracy_counts"]``); ``ax, ay, az`` Android's
``TYPE_ACCELEROMETER`` values in m/s^2, gravity included, device axes:
copied as they are.  The three counts of the validation layout are
cumulative on every line (the app's algorithm, the foot-switch ground-truth
device, Android's hardware step counter): they are part of the file, so
they come as the ``step_counts`` stream (columns ``app``,
``ground_truth``, ``android_hw``).  The optimisation folders keep their
ground truth in a separate ``stepcounter.csv`` (foot switches): that is an
annotation, not part of the file; :func:`core.importers.load_recording` adds it
(:mod:`core.importers.beside`).

A folder is read through its ``accelerometer.csv`` (``.gz`` allowed), and the
folder's ``metadata.txt`` (``accelerometer : MPU6515 Accelerometer``), when
there is one next to the file, names the chip in ``device["accelerometer"]``.
A line with another number of fields than the first one, or a field that is
not a number (the time: an integer), is a bad line: skipped and counted, or,
past 100 or 1 % of the lines, a :class:`RecordingError` naming the first.
Absolute time is unknown.

Streams: ``acc``, and ``step_counts`` in the validation layout.
"""

from __future__ import annotations

import os
import re
import warnings

import numpy as np

from core.conventions import ACC
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import (
    EXTRA_STREAM_SPECS, STEP_COUNTS, FileSet, feed_lines, finish, head_lines, is_zip, open_text,
)
from core.importers._csv import ColumnBuffer, fixed_rows

FORMAT = "oxford-step-counter"

#: number of fields -> (layout, names of the fields)
LAYOUTS = {
    5: ("optimisation", ["t_ns", "accuracy", "ax", "ay", "az"]),
    7: ("validation", ["t_ns", "ax", "ay", "az", "steps_app_algorithm", "steps_ground_truth_device",
                       "steps_android_hw_counter"]),
}
COUNTERS = ["app", "ground_truth", "android_hw"]

_INT = re.compile(r"^\d{6,19}$")


def looks_like(head: str) -> bool:
    """True if the first lines of a text are lines of one of the two layouts (at least 3, and nine in ten).

    Besides the shape (an integer time of 6-19 digits, numbers, the
    accuracy flag 0-3 or three whole non-negative counts), the times must
    not go back and the median ``|a|`` must be 3-30 m/s^2 (gravity included).
    """
    lines = head_lines(head)
    rows = [ln.strip().split(",") for ln in lines]
    k = max(LAYOUTS, key=lambda n: sum(len(r) == n for r in rows))
    t, v = [], []
    for r in rows:
        if len(r) != k or not _INT.match(r[0]):
            continue
        try:
            v.append([float(x) for x in r[1:]])
        except ValueError:
            continue
        t.append(int(r[0]))
    if len(t) < max(3, 0.9 * len(lines)):
        return False
    t, v = np.array(t, dtype=np.int64), np.array(v)
    if k == 5:
        flags, acc = v[:, 0], v[:, 1:4]
        shape_ok = bool(np.all(np.isin(flags, (0.0, 1.0, 2.0, 3.0))))
    else:
        acc, counts = v[:, 0:3], v[:, 3:6]
        shape_ok = bool(np.all((counts >= 0) & (counts == np.round(counts))))
    with np.errstate(all="ignore"):
        g = float(np.median(np.linalg.norm(acc, axis=1)))
    return shape_ok and bool(np.all(t[1:] >= t[:-1])) and 3.0 < g < 30.0


def _accelerometer_file(fs: FileSet) -> str | None:
    for n in fs.names():
        if n.split("/")[-1].lower() == "accelerometer.csv" and n.count("/") <= 1:
            return n
    return None


def looks_like_folder(fs: FileSet) -> bool:
    """True if a folder (or zip) holds an ``accelerometer.csv`` of this format."""
    n = _accelerometer_file(fs)
    return n is not None and looks_like(fs.head(n))


def read_oxford(path: str, *, warn: bool = True,
                max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read an accelerometer file (or a folder or zip holding ``accelerometer.csv``) into a :class:`Recording`.

    See the module doc.  The file is streamed a chunk of lines at a time; a
    gzip stream inflating to over ``max_uncompressed_bytes`` is refused while
    it is read.
    """
    path = str(path)
    if not os.path.exists(path):
        raise RecordingError("cannot open: no such file or folder", path)
    device: dict = {"platform": "android"}
    repairs: list[str] = []
    with np.errstate(all="ignore"):
        if os.path.isdir(path) or is_zip(path):
            with FileSet(path, max_uncompressed_bytes) as fs:
                name = _accelerometer_file(fs)
                if name is None:
                    raise RecordingError("no accelerometer.csv in this folder or archive", path)
                _chip(fs, device)
                with fs.text(name) as text:
                    rec = _parse(text, fs.where(name), repairs)
                repairs += fs.repairs
        else:
            folder = os.path.dirname(os.path.abspath(path))
            if os.path.basename(path).lower().startswith("accelerometer") and \
                    os.path.isfile(os.path.join(folder, "metadata.txt")):
                with FileSet(folder, max_uncompressed_bytes) as fs:
                    _chip(fs, device)
            with open_text(path, repairs, max_uncompressed_bytes) as text:
                rec = _parse(text, path, repairs)
    rec.device = device
    rec.source = path
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=2)
    return finish(rec, warn=warn)


def _chip(fs: FileSet, device: dict) -> None:
    """``device["accelerometer"]`` from the folder's metadata.txt ("accelerometer : NAME"), if it says so."""
    if "metadata.txt" not in fs.names():
        return
    m = re.search(r"^\s*accelerometer\s*:\s*(.+?)\s*$", fs.read_text("metadata.txt"), re.M | re.I)
    if m:
        device["accelerometer"] = m.group(1)[:200]


def _parse(text, source: str, repairs: list[str]) -> Recording:
    t_buf = ColumnBuffer(1, np.int64)
    v_buf: ColumnBuffer | None = None
    bad: list[RecordingError] = []
    n_lines = 0
    k = 0

    def chunk(first: int, lines: list[str]) -> None:
        nonlocal n_lines, k, v_buf
        nos = [first + i for i, ln in enumerate(lines) if ln.strip()]
        rows = [ln for ln in lines if ln.strip()]
        if not rows:
            return
        if not k:
            k = rows[0].count(",") + 1
            if k not in LAYOUTS:
                raise RecordingError(f"{k} fields: an Oxford step-counter accelerometer file has 5 (t_ns,accuracy,"
                                     "ax,ay,az) or 7 (t_ns,ax,ay,az and three step counts)", source, nos[0])
            v_buf = ColumnBuffer(k - 1)
        n_lines += len(rows)
        t, v, _, errs = fixed_rows(rows, list(range(k)), ",", (k, k), names=LAYOUTS[k][1])
        bad.extend(RecordingError(msg, source, nos[j]) for j, msg in errs)
        t_buf.append(t[:, None])
        v_buf.append(v)

    def tail(lineno: int, last: str) -> None:
        if not last.strip():
            return
        if k and last.count(",") + 1 == k:
            chunk(lineno, [last])
        else:
            repairs.append(f"{source}: dropped an incomplete last line {lineno} (no newline: the file was cut off "
                           "mid-write)")

    feed_lines(text, source, repairs, chunk, bad, tail)
    skip_bad_lines(bad, n_lines, source, repairs)
    if not len(t_buf):
        raise RecordingError("no accelerometer lines", source)
    t, v = t_buf.array()[:, 0], v_buf.array()
    layout = LAYOUTS[k][0]
    meta: dict = {
        "source_format": FORMAT,
        "layout": layout,
        "time_base": "t_ns = the file's t_ns (Android SensorEvent.timestamp, ns since boot); absolute time unknown",
    }
    streams = {}
    if layout == "optimisation":
        streams[ACC] = make_stream(ACC, t, v[:, 1:4])
        flags, n = np.unique(v[:, 0][np.isfinite(v[:, 0])], return_counts=True)
        meta["accuracy_counts"] = {f"{f:g}": int(c) for f, c in zip(flags, n)}
    else:
        streams[ACC] = make_stream(ACC, t, v[:, 0:3])
        spec = EXTRA_STREAM_SPECS[STEP_COUNTS]
        streams[STEP_COUNTS] = make_stream(STEP_COUNTS, t, v[:, 3:6], COUNTERS, spec["unit"],
                                           "cumulative step counts on every line: the app's algorithm, the "
                                           "foot-switch ground-truth device, Android's hardware step counter")
    return Recording(streams, metadata=meta, repairs=repairs, source=source)
