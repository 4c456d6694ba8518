"""Reader for the Brajdic & Harle (2013) walk-detection / step-counting traces.

A. Brajdic and R. Harle, "Walk detection and step counting on unconstrained
smartphones", UbiComp 2013 (data: Cambridge Apollo repository).  One file a
walk, ``p<person>.<walk>_<Sex>_<age>_<height>cm_<placement>.out`` (binary)
or ``.dat`` (the same records as text); here also gzip (by content).

Format
======
``.out``: big-endian binary, 21-byte records without a header::

    int64 t_ns | int8 sensor type (1 acc, 2 gyro, 3 mag) | float32 x | float32 y | float32 z

(numpy ``[('t', '>i8'), ('type', 'i1'), ('v', '>f4', 3)]``).  ``.dat``: one
record a line, ``t_ns type x y z`` separated by spaces.  Records of the three
sensors are interleaved in time order.

A record whose type is not 1, 2 or 3 or whose time is not positive (a text
line: fields missing or not numbers) is a bad record: skipped and counted,
or, past 100 or 1 % of the records, a :class:`RecordingError` naming the
first (its record number, counted from 1, stands where a text format names
the line).  A binary file whose length is not a whole number of records was
cut off mid-write: the cut record is dropped, with a line in ``repairs``.

Time, units and axes
====================
``t_ns`` is the file's timestamp as it is: integer nanoseconds of the phone's
uptime clock (Android ``SensorEvent.timestamp``); absolute time is unknown.
Values are Android ``SensorEvent.values`` in the device frame: m/s^2 with
gravity (median ``|a|`` 9.2-9.5 on the real walks), rad/s and uT; copied
(float32 widened to float64).  The file name's height band and the
dataset's step counts and walk windows are annotations of the dataset, not
of the file: :func:`core.importers.load_recording` adds the step count beside the trace
(:mod:`core.importers.beside`), the benchmark reader (``benchmarks.datasets.brajdic_harle``) the rest.

Streams: ``acc``, ``gyro``, ``mag``.
"""

from __future__ import annotations

import re
import warnings

import numpy as np

from core.conventions import ACC, GYRO, MAG
from core.recording import (
    MAX_BAD_LINES, MAX_UNCOMPRESSED_BYTES, ByteChunks, DamagedFileWarning, Recording, RecordingError, make_stream,
    skip_bad_lines,
)
from core.importers._common import feed_lines, finish, head_bytes, head_lines, open_binary, open_text
from core.importers._csv import ColumnBuffer, fixed_rows

FORMAT = "brajdic-harle"

#: one binary record
RECORD = np.dtype([("t", ">i8"), ("type", "i1"), ("v", ">f4", 3)])
#: sensor type code -> stream
TYPES = {1: ACC, 2: GYRO, 3: MAG}

_TEXT_LINE = re.compile(r"^\s*\d{1,19}[ \t]+[123][ \t]+\S+[ \t]+\S+[ \t]+\S+\s*$")
#: records looked at to recognise a binary file
_HEAD_RECORDS = 64


def looks_like_binary(head: bytes) -> bool:
    """True if the first bytes of a file are records of the binary format.

    Of the first 64 records (at least 3), nine in ten must have a type of
    1, 2 or 3, a positive time and finite values below 10^4, and their
    times must advance by less than 10 s from one to the next: random bytes
    pass the type test alone with odds of 3 in 256 a record, and text never
    (its ninth byte is a character).
    """
    n = min(len(head) // RECORD.itemsize, _HEAD_RECORDS)
    if n < 3:
        return False
    d = np.frombuffer(head[:n * RECORD.itemsize], dtype=RECORD)
    t = d["t"].astype(np.int64)
    with np.errstate(all="ignore"):  # random float32 bits: signalling NaNs
        v = d["v"].astype(np.float64)
        ok = np.isin(d["type"], (1, 2, 3)) & (t > 0) & np.all(np.isfinite(v) & (np.abs(v) < 1e4), axis=1)
    t = t[ok]
    return bool(ok.sum() >= max(3, 0.9 * n) and np.all(np.abs(np.diff(t)) < 10_000_000_000))


def looks_like_text(head: str) -> bool:
    """True if the first lines of a text are ``t_ns type x y z`` records (at least 3, and nine lines in ten)."""
    lines = head_lines(head)
    good = 0
    for ln in lines:
        if _TEXT_LINE.match(ln):
            try:
                [float(x) for x in ln.split()[2:5]]
            except ValueError:
                continue
            good += 1
    return good >= max(3, 0.9 * len(lines))


def read_brajdic(path: str, *, warn: bool = True,
                 max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a ``.out`` (binary) or ``.dat`` (text) trace, plain or gzip, into a :class:`Recording` (see the module doc).

    Binary or text is decided by content.  The file is streamed: a chunk of
    records at a time into growing arrays; a gzip stream inflating to over
    ``max_uncompressed_bytes`` is refused while it is read.
    """
    path = str(path)
    head = head_bytes(path, RECORD.itemsize * _HEAD_RECORDS)
    with np.errstate(all="ignore"):
        if looks_like_binary(head) or b"\x00" in head[:1024]:  # text has no NUL
            return _read_binary(path, warn, max_uncompressed_bytes)
        return _read_text(path, warn, max_uncompressed_bytes)


def _read_binary(path: str, warn: bool, limit: int | None) -> Recording:
    size = RECORD.itemsize
    t_buf, typ_buf, v_buf = ColumnBuffer(1, np.int64), ColumnBuffer(1, np.int64), ColumnBuffer(3)
    bad: list[RecordingError] = []
    repairs: list[str] = []
    n_records = 0
    carry = b""
    with open_binary(path) as f:
        chunks = ByteChunks(f, path, limit=limit)
        for data in chunks:
            buf = carry + data if carry else data
            n = len(buf) // size
            carry = buf[n * size:]
            d = np.frombuffer(buf[:n * size], dtype=RECORD)
            t = d["t"].astype(np.int64)
            typ = d["type"].astype(np.int64)
            ok = np.isin(typ, (1, 2, 3)) & (t > 0)
            for j in np.flatnonzero(~ok)[:MAX_BAD_LINES + 1 - len(bad)]:
                k = n_records + int(j) + 1
                what = (f"sensor type {int(typ[j])} is not 1 (acc), 2 (gyro) or 3 (mag)" if typ[j] not in (1, 2, 3)
                        else f"time {int(t[j])} ns is not positive")
                bad.append(RecordingError(f"record {k} (byte {(k - 1) * size}): {what}", path, k))
            n_records += n
            t_buf.append(t[ok][:, None])
            typ_buf.append(typ[ok][:, None])
            v_buf.append(d["v"][ok].astype(np.float64))
            if len(bad) > MAX_BAD_LINES:
                break
        else:
            if chunks.problem is not None:
                if not n_records:
                    raise RecordingError(f"corrupt gzip data: {chunks.problem}", path)
                repairs.append(f"{path}: {chunks.problem}; kept the {n_records} whole records before the damage")
            elif carry:
                repairs.append(f"{path}: dropped an incomplete last record ({len(carry)} of {size} bytes: the file "
                               "was cut off mid-write)")
    skip_bad_lines(bad, n_records, path, repairs)
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=4)
    return _build(path, t_buf.array()[:, 0], typ_buf.array()[:, 0], v_buf.array(), "binary (.out)", n_records,
                  repairs, warn)


def _read_text(path: str, warn: bool, limit: int | None) -> Recording:
    t_buf, typ_buf, v_buf = ColumnBuffer(1, np.int64), ColumnBuffer(1, np.int64), ColumnBuffer(3)
    bad: list[RecordingError] = []
    repairs: list[str] = []
    n_lines = 0
    names = ["t_ns", "type", "x", "y", "z"]

    def chunk(first: int, lines: list[str]) -> None:
        nonlocal n_lines
        nos = [first + i for i, ln in enumerate(lines) if ln.strip()]
        rows = [ln for ln in lines if ln.strip()]
        n_lines += len(rows)
        if not rows:
            return
        t, v, kept, errs = fixed_rows(rows, [0, 1, 2, 3, 4], None, (5, 5), names=names)
        bad.extend(RecordingError(msg, path, nos[j]) for j, msg in errs)
        typ = v[:, 0]
        ok = np.isin(typ, (1.0, 2.0, 3.0)) & (t > 0)
        rows_kept = np.flatnonzero(kept)
        for j in np.flatnonzero(~ok):
            what = (f"sensor type {typ[j]!r} is not 1 (acc), 2 (gyro) or 3 (mag)" if typ[j] not in (1.0, 2.0, 3.0)
                    else f"time {int(t[j])} ns is not positive")
            bad.append(RecordingError(what, path, nos[rows_kept[j]]))
        t_buf.append(t[ok][:, None])
        typ_buf.append(typ[ok].astype(np.int64)[:, None])
        v_buf.append(v[ok, 1:4])

    def tail(lineno: int, last: str) -> None:
        if last.strip():
            repairs.append(f"{path}: dropped an incomplete last line {lineno} (no newline: the trace was cut off "
                           "mid-write; its last number may be cut short)")

    with open_text(path, repairs, limit) as text:
        feed_lines(text, path, repairs, chunk, bad, tail)
    bad.sort(key=lambda e: e.line or 0)
    skip_bad_lines(bad, n_lines, path, repairs)
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=4)
    return _build(path, t_buf.array()[:, 0], typ_buf.array()[:, 0], v_buf.array(), "text (.dat)", n_lines, repairs,
                  warn)


def _build(path, t, typ, v, encoding, n_records, repairs, warn) -> Recording:
    streams = {name: make_stream(name, t[typ == code], v[typ == code]) for code, name in TYPES.items()}
    meta = {
        "source_format": FORMAT,
        "encoding": encoding,
        "records": int(n_records),
        "time_base": "t_ns = the file's timestamps (the phone's uptime clock, ns); absolute time unknown",
    }
    rec = Recording(streams, device={}, metadata=meta, repairs=repairs, source=path)
    return finish(rec, warn=warn)
