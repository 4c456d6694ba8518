"""Sensor recordings: the in-memory data model and the project's file format.

A recording is a set of per-sensor event streams, each with its own
timestamps (phones do not sample their sensors together).  Units, axes and
the time base follow :mod:`core` (SI, Android device frame, ``t_ns``).

File format ``pdr-recording`` version 1
---------------------------------------
Plain UTF-8 text, optionally gzip-compressed (file name ending in ``.gz``)::

    # pdr-recording 1
    # {"format": "pdr-recording", "format_version": 1, "streams": {...}, "device": {...}, "metadata": {...}, ...}
    acc,1000000000,0.12,4.51,8.63
    gyro,1000200000,0.001,-0.02,0.003
    mag,1001000000,12.5,-20.1,-40.3
    gps,1001000000,47.3769,8.5417,420.0,5.0,1.3,87.0

* line 1 is the magic line, line 2 the JSON header (one line).  The header
  names every stream with its value ``columns``, ``unit`` and a note; it
  also carries ``time`` (time base), ``axes`` (axis convention), ``device``
  and free ``metadata``.
* every further line is one sensor event: stream name, integer nanosecond
  timestamp on the sensor clock, then the stream's values.  Floats are
  written with :func:`repr`, so reading gives back exactly the written value.
* a recording may carry several devices: the recording phone's streams have
  the plain names, another device's are ``<kind>@<device>`` (``acc@left_foot``,
  ``mag@waist``: the columns and units of ``<kind>``); see :mod:`core.foot.devices`;
* rows may come in any order (a live recorder appends them as they arrive);
  blank lines and further ``#`` comment lines are ignored.

Readers reject what they cannot read with a :class:`RecordingError` naming
the file, the line and the problem.  Damage is repaired where the rest of
the walk can be trusted, each repair with a :class:`DamagedFileWarning` and a
line in :attr:`Recording.repairs`: a gzip stream cut off part-way (what
came before the damage is kept), a last line without its newline (dropped:
a recorder killed mid-write), and a few bad event lines (skipped and
counted; more than :data:`MAX_BAD_LINES` or 1 % of the event lines reject the
file naming the first).  Header fields are type-checked, and the header's
``format`` and ``format_version`` (when present) must agree with the magic
line.  Timestamps that go backwards or repeat
within a stream (real phones do this) are repaired: events are sorted by
time and exact repeats dropped, with a :class:`TimestampRepairWarning` and a
line in :attr:`Recording.repairs` saying how many.

Readers stream (this one and :mod:`core.importers`): a file is read a chunk
of lines at a time (:class:`ByteChunks`, :class:`TextLines`) into growing
arrays, so memory holds the recording (8 bytes a timestamp and a value) and
little more, never the file's text; a gzip stream or archive member that
inflates beyond :data:`MAX_UNCOMPRESSED_BYTES` (2 GiB) is refused while it
is read.  The writers refuse a header the reader would refuse
(:func:`header_line`).
"""

from __future__ import annotations

import gzip
import io
import json
import math
import os
import warnings
import zipfile
import zlib
from array import array
from dataclasses import dataclass, field
from typing import IO, Iterable, Iterator

import numpy as np

from core import __version__
from core.conventions import ACC, GNSS_STATUS, GPS, GYRO, MAG, ROTVEC, STANDARD_GRAVITY_M_S2
from core.validation import gap_free_rate_hz, validate_recording

MAGIC = "# pdr-recording"
FORMAT_NAME = "pdr-recording"
FORMAT_VERSION = 1

TIME_BASE = "t_ns: integer nanoseconds on the sensor clock (Android SensorEvent.timestamp)"
AXES = "android-device: x right, y towards the top edge, z out of the screen"

#: Default description of the known streams (columns, unit, note).
STREAM_SPECS: dict[str, dict] = {
    ACC: {"columns": ["x", "y", "z"], "unit": "m/s^2", "note": "accelerometer, gravity included"},
    GYRO: {"columns": ["x", "y", "z"], "unit": "rad/s", "note": "gyroscope"},
    MAG: {"columns": ["x", "y", "z"], "unit": "uT", "note": "magnetometer"},
    GPS: {
        "columns": ["lat_deg", "lon_deg", "alt_m", "hacc_m", "speed_m_s", "course_deg"],
        "unit": "deg,deg,m,m,m/s,deg",
        "note": "GNSS fix, WGS-84; hacc_m is the 68 % horizontal accuracy radius; speed_m_s the ground speed "
                "and course_deg its compass bearing (clockwise from true north) where the receiver gives them; "
                "nan if unknown",
    },
    ROTVEC: {
        "columns": ["w", "x", "y", "z"],
        "unit": "1",
        "note": "the phone's own attitude estimate as an ENU<-device quaternion (w, x, y, z)",
    },
    GNSS_STATUS: {
        "columns": ["n_used", "cn0_4th_dbhz"],
        "unit": "1,dB-Hz",
        "note": "GNSS receiver status at a fix (Android GnssStatus or NMEA GSA/GSV): satellites used in the fix "
                "and the carrier-to-noise density of the 4th strongest of them (nan with fewer than 4); an "
                "importer may add a third column, n_view, the satellites in view (unit '1,dB-Hz,1')",
    },
}

#: Units a file may declare per stream kind, with the factor to the unit used inside :mod:`core`
#: (the first one of each kind).  An empty or missing unit means the first one.
UNITS: dict[str, dict[str, float]] = {
    ACC: {"m/s^2": 1.0, "m/s2": 1.0, "g": STANDARD_GRAVITY_M_S2},
    GYRO: {"rad/s": 1.0, "deg/s": math.pi / 180.0},
    MAG: {"uT": 1.0, "\u00b5T": 1.0, "\u03bcT": 1.0, "mT": 1000.0, "nT": 1e-3, "G": 100.0},
    GPS: {STREAM_SPECS[GPS]["unit"]: 1.0, "deg,deg,m,m": 1.0},
    ROTVEC: {"1": 1.0},
    GNSS_STATUS: {"1,dB-Hz": 1.0, "1,dB-Hz,1": 1.0},  # the second with a third column, satellites in view
}

#: fewest events of a stream for the checks of its values against its unit
MIN_EVENTS_FOR_UNIT_CHECK = 50
#: a gyroscope in rad/s whose 99th percentile of |w| exceeds this is taken to be in deg/s
#: (2000 deg/s, the largest range of phone gyroscopes, is 34.9 rad/s; a walking phone turns at 0.5-5 rad/s)
GYRO_P99_MAX_RAD_S = 35.0


#: Order in which simultaneous events of different streams are processed.
STREAM_ORDER = (GYRO, ACC, MAG, ROTVEC, GNSS_STATUS, GPS)


class RecordingError(ValueError):
    """Input that cannot be read; ``str()`` is one line naming file, line and problem."""

    def __init__(self, message: str, path: str | None = None, line: int | None = None):
        self.path = path
        self.line = line
        self.message = _one_line(message)
        where = ""
        if path is not None:
            where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(_one_line(where) + self.message)


def _one_line(text: str) -> str:
    """``text`` on one line whatever the file held (a quoted CSV field, a file name, may hold a newline)."""
    return str(text).replace("\r", "\\r").replace("\n", "\\n")


class MissingSensorError(RecordingError):
    """A stream that a stage needs is absent from the recording."""


class TimestampRepairWarning(UserWarning):
    """Timestamps went backwards or repeated and were repaired."""


class SensorSubstitutedWarning(UserWarning):
    """A sensor's usual source was missing and another one stands in for it (e.g. the uncalibrated gyroscope)."""


class DamagedFileWarning(UserWarning):
    """Part of a damaged file was dropped (a cut gzip, a cut last line, a few bad lines); the rest was read."""


#: bad event lines skipped rather than rejecting the file: at most this fraction of the event lines ...
MAX_BAD_LINE_FRACTION = 0.01
#: ... and at most this many (more is a :class:`RecordingError` naming the first bad line)
MAX_BAD_LINES = 100


def bad_lines_tolerated(n_bad: int, n_lines: int) -> bool:
    """True if ``n_bad`` damaged lines out of ``n_lines`` may be skipped (see :data:`MAX_BAD_LINES`)."""
    return n_bad <= MAX_BAD_LINES and n_bad <= MAX_BAD_LINE_FRACTION * n_lines


def skip_bad_lines(bad: list[RecordingError], n_lines: int, source: str, repairs: list[str]) -> None:
    """Skip the bad lines ``bad`` (errors naming their lines, in file order) of ``n_lines``, or refuse the file.

    The one rule of every reader (:func:`bad_lines_tolerated`): a few are
    skipped and counted in ``repairs`` ("skipped 3 bad line(s) of 9000
    (first: line 17: ...)"); more are a :class:`RecordingError` naming the
    first.  A reader stops at the first bad line past :data:`MAX_BAD_LINES`,
    so more than that many are counted as "over 100".
    """
    if not bad:
        return
    first = bad[0]
    if not bad_lines_tolerated(len(bad), n_lines):
        count = len(bad) if len(bad) <= MAX_BAD_LINES else f"over {MAX_BAD_LINES}"
        more = (f" ({count} bad lines of {n_lines}: too many to skip; at most {MAX_BAD_LINES} and 1 % are skipped)"
                if len(bad) > 1 else "")
        raise RecordingError(first.message + more, first.path, first.line)
    repairs.append(f"{source}: skipped {len(bad)} bad line(s) of {n_lines} (first: line {first.line}: "
                   f"{first.message})")


# ---------------------------------------------------------------------------
# streaming input: a file's bytes (gunzipped by content) -> complete text lines, a chunk at a time

#: largest uncompressed size read from a gzip stream or an archive member (2 GiB: over a day of events at
#: 250 a second in the project format); a larger one is refused (a decompression bomb, or a walk to split)
MAX_UNCOMPRESSED_BYTES = 2 * 1024 ** 3
#: bytes read (or inflated) at a time: the text of a file is never in memory whole, only a chunk of it
CHUNK_BYTES = 1 << 18
#: a line longer than this is not a line of any format read here; it is refused rather than held in memory
MAX_LINE_BYTES = 16 << 20
GZIP_MAGIC = b"\x1f\x8b"


def size_text(n: int) -> str:
    """A byte count for messages: ``2.0 GiB`` / ``400.0 MiB`` / ``512 bytes``."""
    for unit, k in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << k:
            return f"{n / (1 << k):.1f} {unit}"
    return f"{n} bytes"


def over_limit_error(what: str, limit: int, source: str, size: int | None = None) -> RecordingError:
    """The one-line refusal of input larger than ``limit`` bytes uncompressed (``size``: its declared size).

    ``what`` names it ("the gzip stream", "archive member 'Gyroscope.csv'").
    """
    amount = (f"is {size_text(size)} ({size} bytes) uncompressed, over" if size is not None
              else "inflates to more than")
    return RecordingError(f"{what} {amount} the limit of {size_text(limit)} ({limit} bytes) for what is read "
                          "(core.recording.MAX_UNCOMPRESSED_BYTES): refused as a decompression bomb (a real walk "
                          "that long must be split)", source)


#: what reading a file object may raise besides OSError (a zip member: a bad CRC, corrupt deflate data, an
#: encrypted member, a compression method Python lacks)
READ_ERRORS = (OSError, EOFError, zipfile.BadZipFile, zlib.error, RuntimeError, NotImplementedError)


class ByteChunks:
    """The bytes of a binary file object, a chunk of about :data:`CHUNK_BYTES` at a time.

    Gzip input (by content: the gzip magic, whatever the name says;
    several members are read one after the other) is inflated as it is
    read.  A gzip stream cut off or corrupt part-way ends the chunks at the
    damage and sets :attr:`problem` (``"the gzip stream is truncated"``,
    ``"corrupt gzip data (...)"``, ``"trailing garbage after the gzip
    stream"``); it is ``None`` after a whole stream.  More than ``limit``
    bytes of inflated output (of any output when ``inflated`` is true: an
    archive member that was itself inflated, named ``what``) is the
    :class:`RecordingError` of :func:`over_limit_error`, raised while
    inflating, before the output is in memory.  Read errors are a
    :class:`RecordingError` naming ``source``.
    """

    def __init__(self, f: IO[bytes], source: str, *, limit: int | None = MAX_UNCOMPRESSED_BYTES,
                 inflated: bool = False, what: str = "the archive member", chunk: int = CHUNK_BYTES):
        self.f = f
        self.source = source
        self.limit = limit
        self.inflated = inflated
        self.what = what
        self.chunk = chunk
        self.problem: str | None = None
        self.gzipped = False
        #: bytes delivered so far
        self.total = 0

    def _read(self) -> bytes:
        try:
            return self.f.read(self.chunk)
        except READ_ERRORS as e:
            raise RecordingError(f"cannot read: {getattr(e, 'strerror', None) or e}", self.source) from None

    def _out(self, data: bytes, what: str) -> bytes:
        self.total += len(data)
        if self.limit is not None and self.total > self.limit:
            raise over_limit_error(what, self.limit, self.source)
        return data

    def __iter__(self) -> Iterator[bytes]:
        head = self._read()
        while 0 < len(head) < 2:  # one byte cannot tell gzip from text
            more = self._read()
            if not more:
                break
            head += more
        if head[:2] == GZIP_MAGIC:
            self.gzipped = True
            yield from self._inflate(head)
            return
        data = head
        while data:
            yield self._out(data, self.what) if self.inflated else data
            data = self._read()

    def _inflate(self, data: bytes) -> Iterator[bytes]:
        what = "the gzip stream"
        d = zlib.decompressobj(16 + zlib.MAX_WBITS)
        at_end = False  # the input is exhausted
        while True:
            try:
                out = d.decompress(data, self.chunk)
            except zlib.error as e:
                self.problem = f"corrupt gzip data ({e})"
                return
            data = d.unconsumed_tail
            if out:
                yield self._out(out, what)
            if d.eof:
                rest = d.unused_data
                while len(rest) < 2 and not at_end:
                    more = self._read()
                    at_end = not more
                    rest += more
                if rest[:2] == GZIP_MAGIC:  # another gzip member follows
                    d = zlib.decompressobj(16 + zlib.MAX_WBITS)
                    data = rest
                    continue
                while not rest.strip(b"\x00"):  # nothing, or NUL padding, after the last member
                    if at_end:
                        return
                    rest = self._read()
                    at_end = not rest
                self.problem = "trailing garbage after the gzip stream"
                return
            if data or len(out) == self.chunk:
                continue  # more output is pending from the input already given
            if at_end:
                try:
                    out = d.flush()
                except zlib.error as e:
                    self.problem = f"corrupt gzip data ({e})"
                    return
                if out:
                    yield self._out(out, what)
                if not d.eof:
                    self.problem = "the gzip stream is truncated"
                    return
                continue
            data = self._read()
            at_end = not data


def gunzip_partial(data: bytes, limit: int | None = MAX_UNCOMPRESSED_BYTES) -> tuple[bytes, str | None]:
    """Decompress gzip ``data``; a truncated or corrupt stream gives the complete lines before the damage.

    Returns ``(bytes, problem)`` with ``problem`` ``None`` when the stream was
    whole.  (The readers stream instead: :class:`ByteChunks`.)
    """
    chunks = ByteChunks(io.BytesIO(data), "<bytes>", limit=limit)
    raw = b"".join(chunks)
    problem = chunks.problem
    if problem is not None:  # the last line was cut by the damage: keep complete lines only
        raw = raw[:raw.rfind(b"\n") + 1]
        problem += " (its cut last line dropped)"
    return raw, problem


def _decode_replace(data: bytes) -> str:
    return data.decode("utf-8", errors="replace")


class TextLines:
    """The complete lines of a :class:`ByteChunks`, a chunk of lines at a time.

    Iterating gives ``(number of the first line, lines)`` with the lines
    without their newlines; a chunk always ends at a line end, so ``decode``
    (bytes -> str, called once per chunk) never sees half a character.  A
    UTF-8 byte order mark at the start is dropped.  After the iteration
    :attr:`tail` is what followed the last newline (``""`` when the text
    ends with one; otherwise a last line cut mid-write) and :attr:`tail_line`
    its line number; when the gzip stream was damaged (:attr:`problem`) the
    tail is ``""`` (only complete lines are kept) and :attr:`kept_bytes`
    counts the bytes before the damage.  With ``split_cr`` a lone ``"\\r"``
    ends a line too (``decode`` then turns ``"\\r\\n"`` and ``"\\r"`` into
    ``"\\n"``).  A line over :data:`MAX_LINE_BYTES` is a :class:`RecordingError`.
    """

    def __init__(self, chunks: ByteChunks, source: str, decode=_decode_replace, split_cr: bool = False):
        self.chunks = chunks
        self.source = source
        self.decode = decode
        self.split_cr = split_cr
        self.tail = ""
        self.tail_line = 1
        self.kept_bytes = 0
        #: the damage has been noted (see :func:`core.importers._common.note_damage`)
        self.noted = False

    @property
    def gzipped(self) -> bool:
        return self.chunks.gzipped

    @property
    def problem(self) -> str | None:
        """What was wrong with the gzip stream (its cut last line dropped), or ``None``."""
        p = self.chunks.problem
        return None if p is None else p + " (its cut last line dropped)"

    def __iter__(self) -> Iterator[tuple[int, list[str]]]:
        carry = b""
        lineno = 1
        first = True
        for chunk in self.chunks:
            buf = carry + chunk if carry else chunk
            cut = buf.rfind(b"\n")
            if self.split_cr:
                cut = max(cut, buf.rfind(b"\r", 0, len(buf) - 1))  # a "\r" at the end may be half a "\r\n"
            if cut < 0:
                carry = buf
                if len(carry) > MAX_LINE_BYTES:
                    raise RecordingError(f"a line longer than {size_text(MAX_LINE_BYTES)}: not a line of a "
                                         "recording", self.source, lineno)
                continue
            body, carry = buf[:cut + 1], buf[cut + 1:]
            if first:
                body = body[3:] if body[:3] == b"\xef\xbb\xbf" else body
                first = False
            lines = self.decode(body).split("\n")
            lines.pop()  # "" after the last newline
            yield lineno, lines
            lineno += len(lines)
        self.kept_bytes = self.chunks.total - len(carry)
        self.tail_line = lineno
        if self.chunks.problem is not None:
            return  # the damage cut the last line: complete lines only
        if first:
            carry = carry[3:] if carry[:3] == b"\xef\xbb\xbf" else carry
        lines = self.decode(carry).split("\n") if carry else [""]
        self.tail = lines.pop()
        if lines:  # "\r" at the very end, turned into a line end by decode
            yield lineno, lines
            self.tail_line = lineno + len(lines)


class WholeText:
    """A text already in memory with the interface of :class:`TextLines` (one chunk of lines, then the tail)."""

    gzipped = False
    problem = None

    def __init__(self, text: str):
        self._lines = text.split("\n")
        self.tail = self._lines[-1]
        self.tail_line = len(self._lines)

    def __iter__(self) -> Iterator[tuple[int, list[str]]]:
        yield 1, self._lines[:-1]


@dataclass
class Stream:
    """One sensor's events: ``t_ns`` (n,) int64 and ``values`` (n, k) float64."""

    name: str
    t_ns: np.ndarray
    values: np.ndarray
    columns: tuple[str, ...]
    unit: str = ""
    note: str = ""

    def __post_init__(self):
        self.t_ns = np.asarray(self.t_ns, dtype=np.int64).reshape(-1)
        self.values = np.asarray(self.values, dtype=np.float64).reshape(len(self.t_ns), len(self.columns))
        self.columns = tuple(self.columns)

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def duration_s(self) -> float:
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9 if len(self) > 1 else 0.0

    @property
    def rate_hz(self) -> float:
        """Event rate (events per second) over the stream without its gaps
        (:func:`core.validation.gap_free_rate_hz`: a 10-hour pause in a 100 Hz walk is 100 Hz, not 0.4),
        0 for fewer than two events."""
        return gap_free_rate_hz(self.t_ns) if self.duration_s > 0 else 0.0

    def interval_stats_s(self, block: int = 64) -> dict:
        """Median interval, its jitter (std), gaps, and changes of the sampling rate.

        A gap is an interval over 2.5 times the *local* median interval (the
        largest median of its block of ``block`` intervals and the two
        neighbouring blocks), so a rate that changes mid-file is not counted
        as thousands of gaps; ``rate_changes`` counts the places where the
        block median changes by more than a factor 1.5 and ``rates_hz``
        lists the rates in file order (one entry per stretch).
        """
        if len(self) < 3:
            return {"median_s": math.nan, "jitter_s": math.nan, "gaps": 0, "rate_changes": 0, "rates_hz": []}
        dt = (self.t_ns[1:].astype(np.float64) - self.t_ns[:-1].astype(np.float64)) * 1e-9
        med = float(np.median(dt))
        nb = max(1, len(dt) // block)
        edges = np.linspace(0, len(dt), nb + 1).astype(np.int64)
        bmed = np.array([np.median(dt[a:b]) for a, b in zip(edges[:-1], edges[1:])])
        ref_b = bmed.copy()
        ref_b[1:] = np.maximum(ref_b[1:], bmed[:-1])
        ref_b[:-1] = np.maximum(ref_b[:-1], bmed[1:])
        ref = np.repeat(ref_b, np.diff(edges))
        gaps = int(np.sum(dt > 2.5 * ref))
        # rate stretches: consecutive blocks whose medians agree within a factor 1.5
        rates, start = [], 0
        changes = 0
        for k in range(1, nb + 1):
            if k == nb or not (bmed[k] > 0 and bmed[start] > 0 and 1 / 1.5 < bmed[k] / bmed[start] < 1.5):
                m = float(np.median(bmed[start:k]))
                rates.append(round(1.0 / m, 3) if m > 0 else math.inf)
                if k < nb:
                    changes += 1
                start = k
        return {"median_s": med, "jitter_s": jitter_s(dt), "gaps": gaps, "rate_changes": changes,
                "rates_hz": rates[:20]}


#: an interval longer than this times the median interval is a gap (counted apart, not jitter)
JITTER_GAP_FACTOR = 2.5


def jitter_s(intervals_s, gap_factor: float = JITTER_GAP_FACTOR) -> float:
    """Timing jitter: the standard deviation of the intervals between events (s), gaps left out (an interval
    over ``gap_factor`` times the median is a gap, reported apart).  One definition for ``pdr info`` and the
    app's health panel; nan for fewer than two intervals."""
    dt = np.asarray(intervals_s, dtype=float)
    dt = dt[np.isfinite(dt)]
    if len(dt) < 2:
        return math.nan
    med = float(np.median(dt))
    keep = dt[dt <= gap_factor * med] if med > 0 else dt
    return float(np.std(keep)) if len(keep) >= 2 else math.nan


@dataclass
class Recording:
    """A set of sensor streams with the header information of the file format."""

    streams: dict[str, Stream]
    device: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    #: Human-readable lines describing repairs made while reading (diagnostics as data).
    repairs: list[str] = field(default_factory=list)
    #: Where the recording came from (path or description), for messages.
    source: str = ""
    #: What was wrong with its streams (:class:`core.validation.Finding`, found by the reader).
    problems: list = field(default_factory=list)

    def has(self, name: str) -> bool:
        return name in self.streams and len(self.streams[name]) > 0

    def stream(self, name: str, purpose: str = "") -> Stream:
        """The stream ``name``, or :class:`MissingSensorError` naming it."""
        if not self.has(name):
            why = f" ({purpose})" if purpose else ""
            have = ", ".join(sorted(k for k in self.streams if self.has(k))) or "none"
            raise MissingSensorError(
                f"recording has no '{name}' stream{why}; streams present: {have}", path=self.source or None
            )
        return self.streams[name]

    @property
    def t0_ns(self) -> int:
        return int(min(s.t_ns[0] for s in self.streams.values() if len(s)))

    @property
    def t1_ns(self) -> int:
        return int(max(s.t_ns[-1] for s in self.streams.values() if len(s)))

    @property
    def duration_s(self) -> float:
        return (self.t1_ns - self.t0_ns) * 1e-9

    def merged(self, names: Iterable[str] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All events of ``names`` in time order.

        Returns ``(t_ns, stream_index, row)``: for event ``i`` the value row is
        ``self.streams[order[stream_index[i]]].values[row[i]]`` where ``order``
        is :meth:`stream_order`.  Simultaneous events follow :data:`STREAM_ORDER`.
        """
        order = self.stream_order(names)
        ts, si, rows = [], [], []
        for k, name in enumerate(order):
            s = self.streams[name]
            ts.append(s.t_ns)
            si.append(np.full(len(s), k, dtype=np.int64))
            rows.append(np.arange(len(s), dtype=np.int64))
        if not ts:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
        t = np.concatenate(ts)
        s_idx = np.concatenate(si)
        r = np.concatenate(rows)
        idx = np.lexsort((s_idx, t))
        return t[idx], s_idx[idx], r[idx]

    def stream_order(self, names: Iterable[str] | None = None) -> list[str]:
        names = list(self.streams) if names is None else [n for n in names if n in self.streams]
        rank = {n: i for i, n in enumerate(STREAM_ORDER)}
        return sorted(names, key=lambda n: (rank.get(n, len(rank)), n))

    def events(self, names: Iterable[str] | None = None) -> Iterator[tuple[str, int, tuple[float, ...]]]:
        """Iterate ``(stream_name, t_ns, values)`` in time order, as a live source would deliver them."""
        order = self.stream_order(names)
        t, s_idx, rows = self.merged(order)
        vals = [self.streams[n].values for n in order]
        for ti, si, ri in zip(t.tolist(), s_idx.tolist(), rows.tolist()):
            yield order[si], ti, tuple(vals[si][ri].tolist())

    def slice_time(self, t_start_ns: int, t_end_ns: int) -> "Recording":
        """A copy holding only events with ``t_start_ns <= t_ns < t_end_ns``."""
        streams = {}
        for name, s in self.streams.items():
            m = (s.t_ns >= t_start_ns) & (s.t_ns < t_end_ns)
            streams[name] = Stream(name, s.t_ns[m], s.values[m], s.columns, s.unit, s.note)
        return Recording(streams, dict(self.device), dict(self.metadata), list(self.repairs), self.source,
                         list(self.problems))

    def header(self) -> dict:
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "time": TIME_BASE,
            "axes": AXES,
            "streams": {
                n: {"columns": list(s.columns), "unit": s.unit, "note": s.note} for n, s in self.streams.items()
            },
            "device": self.device,
            "metadata": self.metadata,
            "writer": f"pdr {__version__}",
        }


#: The GPS columns of files written before speed and course were added (read as if speed/course were nan).
GPS_COLUMNS_V1 = ("lat_deg", "lon_deg", "alt_m", "hacc_m")


def _pad_gps(values, columns):
    """GPS values with the older 4 columns -> the current ones, speed and course nan."""
    full = tuple(STREAM_SPECS[GPS]["columns"])
    v = np.asarray(values, dtype=np.float64).reshape(-1, len(columns))
    out = np.full((len(v), len(full)), np.nan)
    out[:, :len(columns)] = v
    return out, full


def make_stream(name: str, t_ns, values, columns=None, unit=None, note=None) -> Stream:
    """A :class:`Stream` with the default columns and unit of a known stream name (or ``kind@device``).

    GPS values with only the first four columns (no speed, no course) are
    padded with nan, so that every GPS stream in memory has the same columns.
    """
    spec = STREAM_SPECS.get(name) or STREAM_SPECS.get(name.partition("@")[0], {})  # "acc@left_foot": an acc
    if name == GPS and columns is None:
        v = np.asarray(values, dtype=np.float64)
        if v.ndim == 2 and v.shape[1] == len(GPS_COLUMNS_V1):
            values, _ = _pad_gps(v, GPS_COLUMNS_V1)
    return Stream(
        name,
        t_ns,
        values,
        tuple(columns or spec["columns"]),
        unit if unit is not None else spec.get("unit", ""),
        note if note is not None else spec.get("note", ""),
    )


# ---------------------------------------------------------------------------
# units


def acc_unit_guess(median_norm: float, low_norm: float) -> str | None:
    """The unit an accelerometer (gravity included) looks like from its median and 10th-percentile ``|a|``.

    About 1 (0.6-1.4) is ``"g"``; 0.6-1.4 g is ``"m/s^2"``, and so is a median
    up to 2.5 g when 90 % of the samples exceed 0.6 g (a phone swinging in a
    hand adds the arm's centripetal acceleration to gravity; linear
    acceleration without gravity keeps passing near zero); anything else is
    ``None`` (unknown).  One rule for the project format and the importers.
    """
    g = STANDARD_GRAVITY_M_S2
    if 0.6 < median_norm < 1.4:
        return "g"
    if 0.6 * g < median_norm < 1.4 * g:
        return "m/s^2"
    if 1.4 * g <= median_norm < 2.5 * g and low_norm > 0.6 * g:
        return "m/s^2"
    return None


def _stillish_median_norm(v: np.ndarray, window: int = 25) -> float:
    """Median ``|v|`` over the calmest quarter of windows of ``window`` samples (the phone still-ish)."""
    norm = np.linalg.norm(v, axis=1)
    norm = norm[np.isfinite(norm)]
    n = len(norm) // window
    if n < 2:
        return float(np.median(norm)) if len(norm) else math.nan
    w = norm[:n * window].reshape(n, window)
    sd = w.std(axis=1)
    calm = sd <= np.percentile(sd, 25)
    return float(np.median(w[calm]))


def convert_units(name: str, unit: str, values: np.ndarray, source: str, repairs: list[str]) -> tuple[np.ndarray, str]:
    """Values of stream ``name`` declared in ``unit`` -> the unit of :mod:`core`; unknown units are an error."""
    kind = name.partition("@")[0]
    table = UNITS.get(kind)
    if table is None:
        return values, unit
    canonical = next(iter(table))
    if not unit:
        return values, canonical
    if unit not in table:
        raise RecordingError(f"stream '{name}' declares unit {unit!r}; a '{kind}' stream takes "
                             f"{', '.join(repr(u) for u in table)}", source, 2)
    factor = table[unit]
    if factor != 1.0:
        repairs.append(f"{source}: stream '{name}' converted from {unit} to {canonical} (x {factor:.6g})")
        values = values * factor
    return values, canonical


#: a gyroscope stuck at its range (saturated) plateaus at a value of at most this per axis (rad/s; phone ranges
#: are 2000 deg/s = 34.9 rad/s and 4000 deg/s = 69.8 rad/s)
GYRO_MAX_RANGE_RAD_S = 70.0


def gyro_saturated(v: np.ndarray, threshold: float = GYRO_P99_MAX_RAD_S) -> bool:
    """True when the fast samples of a gyroscope (``|w|`` over ``threshold``) are mostly an axis stuck at its
    largest value (a plateau: saturation), not a scale (deg/s declared as rad/s reach their maximum once).

    An axis is at its plateau where ``|w|`` is within 1e-6 of the axis' largest ``|w|``, that value is
    reached by three samples or more and is at most :data:`GYRO_MAX_RANGE_RAD_S`."""
    a = np.abs(v[np.all(np.isfinite(v), axis=1)])
    if not len(a):
        return False
    top = a.max(axis=0)
    at = a >= top * (1 - 1e-6)
    plateau = at & ((at.sum(axis=0) >= 3) & (top <= GYRO_MAX_RANGE_RAD_S) & (top > 0))
    fast = np.linalg.norm(a, axis=1) > threshold
    return bool(fast.any()) and float(np.mean(plateau[fast].any(axis=1))) >= 0.5


def check_values_against_units(stream: Stream, source: str, declared: str = "") -> None:
    """A :class:`RecordingError` when a stream's values do not fit its unit (says which unit they look like).

    ``stream`` holds the values converted to the unit of :mod:`core`; ``declared`` is the unit the file
    declared (converted from), so that both ways are checked: data in another unit under the core unit, and
    data already in the core unit under a unit that was converted (an accelerometer declared in g whose
    values are m/s^2 would walk 9.8 times too hard; a magnetometer declared in nT whose values are uT).

    Only for streams of at least :data:`MIN_EVENTS_FOR_UNIT_CHECK` events, and
    only when the values clearly fit another unit: ``acc`` whose median |a|
    while still-ish is about 1 (g) or above 300 (cm/s^2 or mg), ``gyro``
    whose 99th percentile |w| is above :data:`GYRO_P99_MAX_RAD_S` (deg/s) unless
    the fast samples are a plateau (a saturated gyroscope, :func:`gyro_saturated`: the degraded modes
    report it), ``mag`` whose median |B| is above 2000 (nT) or below 1.5 but not 0
    (gauss or mT).  A dead sensor (all zeros) is not a unit problem.
    """
    kind = stream.name.partition("@")[0]
    if len(stream) < MIN_EVENTS_FOR_UNIT_CHECK or kind not in (ACC, GYRO, MAG):
        return
    factor = UNITS[kind].get(declared, 1.0) if declared else 1.0
    v = stream.values
    with np.errstate(all="ignore"):
        if kind == ACC:
            m = _stillish_median_norm(v)
            if not math.isfinite(m):
                return
            norm = np.linalg.norm(v, axis=1)
            low = float(np.nanpercentile(norm, 10))
            if factor != 1.0:
                if acc_unit_guess(m, low) != "m/s^2" and acc_unit_guess(m / factor, low / factor) == "m/s^2":
                    raise RecordingError(f"stream '{stream.name}' is declared in {declared} but its magnitude while "
                                         f"still-ish is {m / factor:.3g} {declared}, not about 1: the values look "
                                         f"like m/s^2 already; declare \"unit\": \"m/s^2\" (converting them would "
                                         f"make every acceleration {factor:.4g} times too large)", source)
                return
            if acc_unit_guess(m, low) == "g":
                raise RecordingError(f"stream '{stream.name}' is declared in m/s^2 but its magnitude while "
                                     f"still-ish is {m:.3g}, about 1: it looks like g; declare \"unit\": \"g\" "
                                     f"(or multiply the values by 9.80665)", source)
            if m > 300.0:
                raise RecordingError(f"stream '{stream.name}' is declared in m/s^2 but its magnitude while "
                                     f"still-ish is {m:.4g}, not about 9.8: it looks like cm/s^2 or mg "
                                     "(divide by 100 or by 101.97)", source)
        elif kind == GYRO:
            norm = np.linalg.norm(v, axis=1)
            norm = norm[np.isfinite(norm)]
            if len(norm) and (p99 := float(np.percentile(norm, 99))) > GYRO_P99_MAX_RAD_S and not gyro_saturated(v):
                raise RecordingError(f"stream '{stream.name}' is declared in {declared or 'rad/s'} but 1 % of its "
                                     f"samples turn faster than {p99:.4g} rad/s (over {GYRO_P99_MAX_RAD_S:g}, the "
                                     "range of phone gyroscopes; a walking phone shows 50-300 deg/s): it looks like "
                                     "deg/s; declare \"unit\": \"deg/s\"", source)
        else:
            norm = np.linalg.norm(v, axis=1)
            norm = norm[np.isfinite(norm)]
            med = float(np.median(norm)) if len(norm) else 0.0
            if factor != 1.0 and (med > 2000.0 or 0.0 < med < 1.5):
                raw = med / factor
                fits = [u for u, f in UNITS[MAG].items() if 15.0 <= raw * f <= 200.0 and u in ("uT", "nT", "mT", "G")]
                like = " or ".join(fits) if fits else "no unit of a magnetometer"
                raise RecordingError(f"stream '{stream.name}' is declared in {declared} but its median |B| is "
                                     f"{raw:.4g} {declared} = {med:.4g} uT (the Earth's field is 25-65 uT): the "
                                     f"values look like {like}"
                                     + (f"; declare \"unit\": \"{fits[0]}\"" if fits else ""), source)
            if med > 2000.0:
                raise RecordingError(f"stream '{stream.name}' is declared in uT but its median |B| is {med:.4g} "
                                     "(the Earth's field is 25-65 uT): it looks like nT; declare \"unit\": \"nT\"",
                                     source)
            if 0.0 < med < 1.5:
                like = "gauss" if med > 0.1 else "mT"
                unit = "G" if med > 0.1 else "mT"
                raise RecordingError(f"stream '{stream.name}' is declared in uT but its median |B| is {med:.4g} "
                                     f"(the Earth's field is 25-65 uT): it looks like {like}; declare "
                                     f"\"unit\": \"{unit}\"", source)


#: a walking phone's accelerometer norm varies by at least this much (standard deviation, m/s^2; about 2-3
#: while walking, under 0.1 for a phone at rest) ...
MOVING_ACC_SD_M_S2 = 1.5
#: ... and its gyroscope turns faster than this for more than 1 % of the samples (rad/s; 50-300 deg/s walking)
MOVING_GYRO_P99_MIN_RAD_S = 0.1


def check_gyro_against_motion(streams: dict, source: str, declared: dict) -> None:
    """A :class:`RecordingError` for a gyroscope declared in deg/s whose values are rad/s already (issue #30).

    One stream alone cannot tell (a still phone's rates look the same in both units); with the accelerometer it
    can: while the acceleration's norm varies like a walk's (standard deviation over :data:`MOVING_ACC_SD_M_S2`),
    a phone's gyroscope turns faster than :data:`MOVING_GYRO_P99_MIN_RAD_S` for more than 1 % of its samples.
    Converted from deg/s, rad/s values are 57 times too small."""
    for name, g in streams.items():
        kind, _, dev = name.partition("@")
        acc = streams.get(ACC + ("@" + dev if dev else ""))
        unit = declared.get(name, "")
        if kind != GYRO or acc is None or UNITS[GYRO].get(unit, 1.0) == 1.0:
            continue
        if len(g) < MIN_EVENTS_FOR_UNIT_CHECK or len(acc) < MIN_EVENTS_FOR_UNIT_CHECK:
            continue
        with np.errstate(all="ignore"):
            a = np.linalg.norm(acc.values, axis=1)
            w = np.linalg.norm(g.values, axis=1)
        a, w = a[np.isfinite(a)], w[np.isfinite(w)]
        if not len(a) or not len(w):
            continue
        sd, p99 = float(np.std(a)), float(np.percentile(w, 99))
        if sd > MOVING_ACC_SD_M_S2 and 0.0 < p99 < MOVING_GYRO_P99_MIN_RAD_S:
            f = UNITS[GYRO][unit]
            raise RecordingError(f"stream '{name}' is declared in {unit} but while the accelerometer shows movement "
                                 f"(|a| varies by {sd:.2g} m/s^2) 99 % of its samples turn slower than {p99 / f:.3g} "
                                 f"{unit} = {p99:.3g} rad/s (a carried phone turns at 50-300 deg/s): the values look "
                                 "like rad/s already; declare \"unit\": \"rad/s\"", source)


# ---------------------------------------------------------------------------
# time bases

#: a sensor stream whose median interval is below this (in "nanoseconds") runs above 20 kHz: its clock is
#: not in nanoseconds (phone sensors run at 1-2000 Hz)
MIN_SENSOR_INTERVAL_NS = 50_000
#: a clock that goes back by more than this within a stream is refused (sorting would interleave two stretches)
MAX_BACKWARDS_S = 1.0
#: fewest events of a stream for the time-base checks
MIN_EVENTS_FOR_TIME_CHECK = 20


def check_time_base(name: str, t_ns: np.ndarray, source: str, lines: list[int] | None = None) -> None:
    """A :class:`RecordingError` when a stream's timestamps are not nanoseconds or jump back by over a second.

    Timestamps in ms or us (or whole seconds) are refused rather than
    converted: at 500-1000 a median interval fits both ms (1-2 kHz) and us
    (1-2 kHz), and a wrong guess would give a confident wrong walk, while
    the writer of the file knows its unit.  A backwards jump of more than
    :data:`MAX_BACKWARDS_S` is refused naming the line (``lines``: the file
    line of each event): sorting would interleave two stretches of the walk.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    if len(t) < 2:
        return
    tf = t.astype(np.float64)
    back = np.flatnonzero(tf[:-1] - tf[1:] > MAX_BACKWARDS_S * 1e9)
    if len(back):
        j = int(back[0]) + 1
        where = lines[j] if lines is not None else None
        prev = f" (line {lines[j - 1]})" if lines is not None else ""
        raise RecordingError(f"stream '{name}': the clock jumps back by {(tf[j - 1] - tf[j]) * 1e-9:.1f} s, from "
                             f"t_ns {int(t[j - 1])}{prev} to {int(t[j])}; sorting would interleave two stretches of "
                             f"the walk: split the file where the clock jumps (or fix the clock)", source, where)
    kind = name.partition("@")[0]
    if kind not in (ACC, GYRO, MAG) or len(t) < MIN_EVENTS_FOR_TIME_CHECK:
        return
    ts = np.sort(tf)
    d = ts[1:] - ts[:-1]
    zero = float(np.mean(d == 0))
    pos = d[d > 0]
    if not len(pos):
        raise RecordingError(f"stream '{name}': all {len(t)} events have the same timestamp: t_ns must be "
                             "integer nanoseconds on the sensor clock", source)
    med = float(np.median(pos))
    if zero > 0.5:
        raise RecordingError(f"stream '{name}': {zero:.0%} of the events repeat the previous timestamp and the "
                             f"distinct ones are a median {med:.6g} apart: the clock is too coarse (whole seconds or "
                             "milliseconds?); t_ns must be integer nanoseconds", source)
    if float(np.median(d)) < MIN_SENSOR_INTERVAL_NS:
        m = float(np.median(d))
        looks = []
        if 0.5 <= m <= 1000:
            looks.append(f"milliseconds ({1e3 / m:.4g} Hz; multiply by 1000000)")
        if 500 <= m < MIN_SENSOR_INTERVAL_NS:
            looks.append(f"microseconds ({1e6 / m:.4g} Hz; multiply by 1000)")
        guess = " or ".join(looks) if looks else "not nanoseconds"
        raise RecordingError(f"stream '{name}': the median interval is {m:.6g} t_ns units, {1e9 / m:.4g} Hz if they "
                             f"were nanoseconds (phone sensors run at 1-2000 Hz): the timestamps look like {guess}; "
                             "t_ns must be integer nanoseconds", source)


# ---------------------------------------------------------------------------
# timestamp repair


def repair_timestamps(stream: Stream) -> tuple[Stream, int, int]:
    """Sort a stream by time and drop exact timestamp repeats.

    Returns ``(stream, n_out_of_order, n_duplicates)``; the stream is returned
    unchanged when nothing needed repair.  Of events sharing a timestamp the
    first one in file order is kept.
    """
    t = stream.t_ns
    if len(t) < 2:
        return stream, 0, 0
    # comparisons, not np.diff: a difference of two int64 timestamps can overflow
    n_back = int(np.sum(t[1:] < t[:-1]))
    if n_back == 0 and not np.any(t[1:] == t[:-1]):
        return stream, 0, 0
    order = np.argsort(t, kind="stable")
    ts = t[order]
    keep = np.ones(len(ts), dtype=bool)
    keep[1:] = ts[1:] != ts[:-1]
    n_dup = int(np.sum(~keep))
    idx = order[keep]
    return Stream(stream.name, t[idx], stream.values[idx], stream.columns, stream.unit, stream.note), n_back, n_dup


def repair_recording(rec: Recording, warn: bool = True) -> Recording:
    """Repair every stream of ``rec`` in place (see :func:`repair_timestamps`) and record what was done, then
    validate the streams against each other (:func:`core.validation.validate_recording`): the last step of
    every reader."""
    for name in list(rec.streams):
        fixed, n_back, n_dup = repair_timestamps(rec.streams[name])
        if n_back or n_dup:
            rec.streams[name] = fixed
            msg = (
                f"{rec.source or 'recording'}: stream '{name}': {n_back} timestamp(s) went backwards "
                f"and {n_dup} repeated; events sorted by time and {n_dup} repeat(s) dropped"
            )
            rec.repairs.append(msg)
            if warn:
                warnings.warn(msg, TimestampRepairWarning, stacklevel=3)
    return validate_recording(rec, warn=warn)


# ---------------------------------------------------------------------------
# writing


def _open_text(path: str, mode: str) -> IO[str]:
    if str(path).endswith(".gz"):
        return io.TextIOWrapper(gzip.open(path, mode + "b"), encoding="utf-8", newline="")
    return open(path, mode, encoding="utf-8", newline="")


def format_row(name: str, t_ns: int, values: Iterable[float]) -> str:
    """One event as a line of the file format (with its newline)."""
    return ",".join([name, str(int(t_ns))] + [repr(float(v)) for v in values]) + "\n"


def header_line(rec: Recording, path: str) -> str:
    """The JSON header line of ``rec`` (with its newline), or a :class:`RecordingError` if the reader would refuse it.

    The header is checked as the reader will see it (after JSON) by the
    reader's own :func:`check_header` -- metadata of the wrong type for the
    keys the product reads (``{"truth": 0}``), a device that is not an
    object, streams that cannot be rows -- so no file is written that
    cannot be read back.
    """
    try:
        text = json.dumps(rec.header(), sort_keys=True)
    except (TypeError, ValueError) as e:
        raise RecordingError(f"cannot write: the header is not JSON ({e})", path) from None
    try:
        check_header(json.loads(text), FORMAT_VERSION, path)
    except RecordingError as e:
        raise RecordingError(f"cannot write: {e.message}", path) from None
    return "# " + text + "\n"


def _copy(obj):
    """A dict's copy (``{}`` for ``None``); anything else as it is, for :func:`header_line` to name."""
    return {} if obj is None else dict(obj) if isinstance(obj, dict) else obj


def write_recording(path: str, rec: Recording) -> None:
    """Write ``rec`` to ``path`` (gzip if it ends in ``.gz``), events in time order.

    A header the reader would refuse is a :class:`RecordingError` before anything is written.
    """
    head = header_line(rec, str(path))
    with _open_text(path, "w") as f:
        f.write(f"{MAGIC} {FORMAT_VERSION}\n")
        f.write(head)
        for name, t, vals in rec.events():
            f.write(format_row(name, t, vals))


class RecordingWriter:
    """Append-only writer for live sessions: each event as it arrives, the header with the first events.

    Each :meth:`add` appends one line; :meth:`flush` (called by the app at
    least once a second) pushes buffered lines to the OS, so a crash loses at
    most the events since the last flush.  Plain text only (gzip cannot be
    read back after an abrupt stop).  The reader accepts a truncated last line
    (see :func:`read_recording` ``allow_truncated_tail``).  A header the
    reader would refuse is a :class:`RecordingError` before the file is made
    (see :func:`header_line`).

    Never a header-only file: the file appears at the first :meth:`flush` that
    has events (written as ``path + ".part"``, synced, then renamed), so a
    writer killed before its first events leaves no file rather than one the
    reader refuses ("the file has a header but no sensor events");
    :meth:`close` without any event writes nothing.
    """

    def __init__(self, path: str, streams: dict[str, dict] | None = None, device=None, metadata=None):
        if str(path).endswith(".gz"):
            raise ValueError("live recordings are written as plain text; compress them after the session")
        self.path = str(path)
        specs = streams or {n: STREAM_SPECS[n] for n in (ACC, GYRO, MAG, GPS)}
        rec = Recording({n: Stream(n, [], np.zeros((0, len(s["columns"]))), s["columns"], s.get("unit", ""),
                                   s.get("note", "")) for n, s in specs.items()},
                        device=_copy(device), metadata=_copy(metadata))
        head = header_line(rec, self.path)  # a header the reader would refuse: nothing is written
        self._head = f"{MAGIC} {FORMAT_VERSION}\n" + head
        self._pending: list[str] = []  # the first events, until the file is made
        self._f = None
        self._closed = False
        self.count = 0

    def add(self, name: str, t_ns: int, values: Iterable[float]) -> None:
        row = format_row(name, t_ns, values)
        if self._f is None:
            self._pending.append(row)
        else:
            self._f.write(row)
        self.count += 1

    def flush(self) -> None:
        if self._f is None:
            if not self._pending:
                return
            part = self.path + ".part"
            with open(part, "w", encoding="utf-8", newline="") as f:
                f.write(self._head + "".join(self._pending))
                f.flush()
                os.fsync(f.fileno())
            os.replace(part, self.path)  # the recording appears with its header and first events
            self._pending = []
            self._f = open(self.path, "a", encoding="utf-8", newline="")
            return
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        if self._closed:
            return
        self.flush()
        self._closed = True
        if self._f is not None:
            self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ---------------------------------------------------------------------------
# reading


def read_recording(path: str, *, allow_truncated_tail: bool = True, warn: bool = True,
                   check_units: bool = True, check_time: bool = True, allow_empty: bool = False,
                   max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a ``pdr-recording`` file.

    Raises :class:`RecordingError` (naming file and line) for an empty file, a
    wrong magic line or header, and for damage beyond what is repaired.
    Repaired, with a :class:`DamagedFileWarning` and a line in
    :attr:`Recording.repairs` (when ``allow_truncated_tail`` is true): a gzip
    stream cut off or corrupt part-way (what came before the damage is
    kept), a last line without its newline (a recorder killed mid-write: it
    is dropped even when it parses, since ``2.586e-0`` may be a cut
    ``2.586e-05``), and a few bad event lines (see :func:`parse_recording`).

    The file is read as a stream (gzip by content, inflated as it is read),
    a chunk of lines at a time, into growing arrays: besides the recording
    itself (8 bytes a timestamp and a value) it takes the file line of each
    event (8 bytes) and a few MiB.  A gzip stream that inflates to over
    ``max_uncompressed_bytes`` (:data:`MAX_UNCOMPRESSED_BYTES`) is refused
    while it is inflated.
    """
    path = str(path)
    try:
        f = open(path, "rb")
    except OSError as e:
        raise RecordingError(f"cannot open: {e.strerror or e}", path) from None
    with f:
        chunks = ByteChunks(f, path, limit=max_uncompressed_bytes)
        return _parse_lines(TextLines(chunks, path), path, allow_truncated_tail=allow_truncated_tail,
                            warn=warn, check_units=check_units, check_time=check_time, allow_empty=allow_empty,
                            repairs=[])


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


#: metadata keys that the product reads, with the type they must have (checked when the file is read,
#: not after a full run)
_METADATA_TYPES = (
    ("unix_offset_ns", _is_int, "an integer (nanoseconds)"),
    ("t0_unix_ns", _is_int, "an integer (nanoseconds)"),
    ("devices", lambda v: isinstance(v, dict) and all(isinstance(d, dict) for d in v.values()),
     "an object of objects (one per device)"),
    ("truth", lambda v: isinstance(v, dict), "an object"),
    ("waypoints_en_m", lambda v: isinstance(v, list) and all(isinstance(p, list) and len(p) == 2
                                                            and all(_is_number(c) for c in p) for p in v),
     "a list of [east, north] number pairs"),
)


def check_header(header, version: int, source: str) -> dict:
    """The header's stream specs, after checking every field's type (a clear error, never a traceback).

    The one check of the reader (line 2 of a file) and the writers
    (:func:`header_line`: nothing is written that the reader would refuse).
    """
    if not isinstance(header, dict) or not isinstance(header.get("streams"), dict) or not header["streams"]:
        raise RecordingError("header must be a JSON object with a non-empty 'streams' object", source, 2)
    if "format" in header and header["format"] != FORMAT_NAME:
        raise RecordingError(f"header 'format' is {header['format']!r}, the magic line says {FORMAT_NAME!r}",
                             source, 2)
    if "format_version" in header:
        fv = header["format_version"]
        if isinstance(fv, bool) or not isinstance(fv, int) or fv != version:
            raise RecordingError(f"header 'format_version' is {fv!r}, the magic line says {version}", source, 2)
    for key in ("device", "metadata"):
        if header.get(key) is not None and not isinstance(header[key], dict):
            raise RecordingError(f"header '{key}' must be a JSON object, found {type(header[key]).__name__}",
                                 source, 2)
    meta = header.get("metadata") or {}
    for key, ok, want in _METADATA_TYPES:
        if key in meta and meta[key] is not None and not ok(meta[key]):
            raise RecordingError(f"header metadata '{key}' must be {want}, found {json.dumps(meta[key])[:60]}",
                                 source, 2)
    specs = {}
    for name, spec in header["streams"].items():
        if not isinstance(spec, dict):
            raise RecordingError(f"header stream '{name}' must be a JSON object with 'columns', found "
                                 f"{type(spec).__name__}", source, 2)
        cols = spec.get("columns")
        if not isinstance(cols, list) or not cols or not all(isinstance(c, str) for c in cols):
            raise RecordingError(f"header stream '{name}' needs a non-empty list of 'columns'", source, 2)
        if "," in name or not name.strip() or name != name.strip():
            raise RecordingError(f"header stream name {name!r} cannot be used in rows", source, 2)
        for key in ("unit", "note"):
            if spec.get(key) is not None and not isinstance(spec[key], str):
                raise RecordingError(f"header stream '{name}': '{key}' must be a string, found "
                                     f"{type(spec[key]).__name__}", source, 2)
        kind = name.partition("@")[0]
        if kind in STREAM_SPECS:
            want = len(STREAM_SPECS[kind]["columns"])
            allowed = {want, len(GPS_COLUMNS_V1)} if kind == GPS else {want, want + 1} if kind == GNSS_STATUS \
                else {want}  # gnss_status may add n_view
            if len(cols) not in allowed:
                raise RecordingError(f"header stream '{name}' declares {len(cols)} columns; a '{kind}' stream has "
                                     f"{' or '.join(str(a) for a in sorted(allowed))} "
                                     f"({', '.join(STREAM_SPECS[kind]['columns'])})", source, 2)
        specs[name] = spec
    return specs


def parse_recording(text: str, source: str = "<text>", *, allow_truncated_tail: bool = True,
                    warn: bool = True, check_units: bool = True, check_time: bool = True,
                    allow_empty: bool = False, _repairs: list[str] | None = None) -> Recording:
    """Parse the text of a ``pdr-recording`` file (see :func:`read_recording`).

    A bad event line (unknown stream, wrong number of values, a value that is
    not a number, a timestamp that is not an int64 nanosecond count, bytes
    that are not UTF-8) is skipped and counted in :attr:`Recording.repairs`
    with a :class:`DamagedFileWarning` as long as the bad lines are at most
    :data:`MAX_BAD_LINES` (100) and at most :data:`MAX_BAD_LINE_FRACTION`
    (1 %) of the event lines; beyond that the file is rejected with a
    :class:`RecordingError` naming the first bad line.  With
    ``allow_truncated_tail=False`` every bad line is an error.

    Units: each stream of a known kind must declare one of :data:`UNITS`
    (or none: the unit of :mod:`core`); ``g``, ``deg/s``, ``mT``, ``nT`` and
    ``G`` are converted (noted in ``repairs``), anything else is a
    :class:`RecordingError` naming the stream, its unit and the accepted
    ones.  With ``check_units`` the values are then checked against the
    unit (:func:`check_values_against_units`).  With ``check_time`` the
    time base is checked (:func:`check_time_base`): timestamps that are not
    nanoseconds, or a clock that jumps back by more than a second, are a
    :class:`RecordingError`.  With ``allow_empty`` a file with a header but
    no events (a live recording killed before its first flush) gives a
    recording with empty streams (noted in ``repairs``) instead of an error.
    """
    return _parse_lines(WholeText(text), source, allow_truncated_tail=allow_truncated_tail, warn=warn,
                        check_units=check_units, check_time=check_time, allow_empty=allow_empty,
                        repairs=list(_repairs or []))


def _parse_lines(text: TextLines | WholeText, source: str, *, allow_truncated_tail: bool, warn: bool,
                 check_units: bool, check_time: bool, allow_empty: bool, repairs: list[str]) -> Recording:
    """The reader of :func:`read_recording` and :func:`parse_recording`."""
    it = iter(text)
    try:
        return _parse_events(it, text, source, allow_truncated_tail, warn, check_units, check_time, allow_empty,
                             repairs)
    except RecordingError:
        if not text.gzipped or allow_truncated_tail:
            raise
        for _ in it:  # a damaged gzip stream is refused before what the damage did to the lines is named
            pass
        if text.problem is not None:
            raise RecordingError(f"cannot read: {text.problem}", source) from None
        raise


def _parse_events(it, text, source, allow_truncated_tail, warn, check_units, check_time, allow_empty,
                  repairs) -> Recording:
    # the magic line and the header: the first two lines (a text without more lines: its tail is line 1 or 2)
    pending: list[str] = []
    at_end = False
    while len(pending) < 2:
        try:
            pending.extend(next(it)[1])
        except StopIteration:
            at_end = True
            break
    head, rest = pending[:2], pending[2:]
    del pending
    if at_end and text.problem is None:
        head.append(text.tail)
    if not head:  # a damaged gzip stream without one complete line
        raise RecordingError(f"cannot read: {text.problem}", source)
    if not head[0].strip() and not _any_text(head, it, text):
        raise RecordingError("empty file: expected the line '# pdr-recording 1' and a JSON header", source, 1)
    first = head[0].strip()
    if not first.startswith(MAGIC):
        raise RecordingError(f"not a pdr-recording: first line must be '{MAGIC} {FORMAT_VERSION}', "
                             f"found {first[:40]!r}", source, 1)
    try:
        version = int(first[len(MAGIC):].strip())
    except ValueError:
        raise RecordingError(f"bad format version in {first[:60]!r}", source, 1) from None
    if version != FORMAT_VERSION:
        raise RecordingError(f"format version {version} is not supported (this reader reads version "
                             f"{FORMAT_VERSION})", source, 1)
    if len(head) < 2 or not head[1].startswith("#"):
        raise RecordingError("missing JSON header line after the magic line", source, 2)
    if "\ufffd" in head[1]:
        raise RecordingError("header line holds bytes that are not UTF-8", source, 2)
    try:
        header = json.loads(head[1][1:])
    except json.JSONDecodeError as e:
        raise RecordingError(f"header is not valid JSON: {e.msg} at column {e.colno + 1}", source, 2) from None
    except RecursionError:
        raise RecordingError("header is not valid JSON: nested too deeply", source, 2) from None
    specs = check_header(header, version, source)
    ncols = {n: len(s["columns"]) for n, s in specs.items()}
    # per stream: timestamps, values (row after row), file line of each event, fields per row, values per row --
    # growing arrays of 8 bytes an entry, viewed as numpy arrays at the end without a copy
    data = {n: (array("q"), array("d"), array("q"), k + 2, k) for n, k in ncols.items()}
    bad: list[RecordingError] = []
    n_events = 0

    def events(lineno: int, lines: list[str]) -> bool:
        """Parse one chunk of event lines; False after too many bad lines (the reader stops)."""
        nonlocal n_events
        i = lineno - 1
        for line in lines:
            i += 1
            line = line.strip()
            if not line or line[0] == "#":
                continue  # a bad byte in a comment does not matter
            n_events += 1
            # fast path; anything unusual goes to _parse_row, which names the problem
            parts = line.split(",")
            d = data.get(parts[0])
            if d is not None and len(parts) == d[3]:
                try:
                    t = int(parts[1])
                    if 0 <= t <= _INT64_MAX:
                        d[1].extend(map(float, parts[2:]))
                        d[0].append(t)
                        d[2].append(i)
                        continue
                except ValueError:
                    del d[1][len(d[0]) * d[4]:]  # the values of this row before its bad one
            try:
                name, t, vals = _parse_row(line, specs, ncols, source, i)
            except RecordingError as e:
                if not allow_truncated_tail:
                    raise
                bad.append(e)
                if len(bad) > MAX_BAD_LINES:
                    return False
                continue
            d = data[name]
            d[0].append(t)
            d[1].extend(vals)
            d[2].append(i)
        return True

    going = events(3, rest)
    del rest
    if going:
        for lineno, lines in it:
            if not events(lineno, lines):
                going = False
                break
    damage = []
    if text.problem is not None:
        if not allow_truncated_tail:
            raise RecordingError(f"cannot read: {text.problem}", source)
        damage.append(f"{source}: {text.problem}; kept the {text.kept_bytes} bytes before the damage")
    elif going and text.tail_line >= 3 and text.tail.strip():
        if allow_truncated_tail and not text.tail.lstrip().startswith("#"):
            damage.append(f"{source}: dropped an incomplete last line {text.tail_line}: no newline (the recording "
                          "was cut off mid-write; its last number may be cut short)")
        else:
            events(text.tail_line, [text.tail])
    repairs.extend(damage)
    if bad:
        skip_bad_lines(bad, n_events, source, repairs)
    n_damage = len(repairs)
    streams = {}
    declared = {}
    for name, spec in specs.items():
        ts, vs, _, _, k = data[name]
        cols = tuple(spec["columns"])
        vals = np.frombuffer(vs, dtype=np.float64).reshape(len(ts), k)
        unit, note = str(spec.get("unit") or ""), str(spec.get("note") or "")
        declared[name] = unit
        vals, unit = convert_units(name, unit, vals, source, repairs)
        if name == GPS and cols == GPS_COLUMNS_V1:  # a file from before speed/course: same meaning, two nan columns
            vals, cols = _pad_gps(vals, cols)
            unit, note = STREAM_SPECS[GPS]["unit"], STREAM_SPECS[GPS]["note"]
        streams[name] = Stream(name, np.frombuffer(ts, dtype=np.int64), vals, cols, unit, note)
    if not any(len(s) for s in streams.values()):
        if not allow_empty:
            raise RecordingError("the file has a header but no sensor events: an empty recording (stopped before "
                                 "its first events were written), nothing to replay", source)
        repairs.append(f"{source}: the file has a header but no sensor events (a recording stopped before its "
                       "first events were written)")
    if check_time:
        for name, s in streams.items():
            check_time_base(name, s.t_ns, source, data[name][2])
    if check_units:
        for s in streams.values():
            check_values_against_units(s, source, declared.get(s.name, ""))
        check_gyro_against_motion(streams, source, declared)
    rec = Recording(streams, device=dict(header.get("device") or {}), metadata=dict(header.get("metadata") or {}),
                    repairs=repairs, source=source)
    if warn:
        for r in repairs[:n_damage]:
            warnings.warn(r, DamagedFileWarning, stacklevel=4)
    return repair_recording(rec, warn=warn)


def _any_text(head: list[str], it, text) -> bool:
    """True if the text is more than whitespace (what follows ``head`` is read to know)."""
    if any(h.strip() for h in head):
        return True
    for _, lines in it:
        if any(ln.strip() for ln in lines):
            return True
    return bool(text.tail.strip())


_INT64_MAX = 2**63 - 1
_INT64_MIN = -2**63


def _parse_row(line: str, specs, ncols, source: str, lineno: int):
    if "\ufffd" in line:
        raise RecordingError("bytes that are not UTF-8 in an event line", source, lineno)
    parts = line.split(",")
    name = parts[0]
    if name not in specs:
        raise RecordingError(f"stream '{name[:40]}' is not declared in the header "
                             f"(declared: {', '.join(specs)})", source, lineno)
    n = ncols[name]
    if len(parts) != n + 2:
        what = "missing" if len(parts) < n + 2 else "extra"
        raise RecordingError(f"{what} columns: stream '{name}' rows have t_ns and {n} values "
                             f"({', '.join(specs[name]['columns'])}), found {len(parts) - 2}", source, lineno)
    try:
        t = int(parts[1])
    except ValueError:
        raise RecordingError(f"timestamp {parts[1][:40]!r} is not an integer nanosecond count",
                             source, lineno) from None
    if not _INT64_MIN <= t <= _INT64_MAX:
        raise RecordingError(f"timestamp {parts[1][:40]} does not fit a 64-bit nanosecond count", source, lineno)
    if t < 0:
        raise RecordingError(f"timestamp {parts[1][:40]} is negative: t_ns counts nanoseconds on the sensor clock "
                             "(from the phone's boot)", source, lineno)
    vals = []
    for col, p in zip(specs[name]["columns"], parts[2:]):
        try:
            vals.append(float(p))
        except ValueError:
            raise RecordingError(f"value {p[:40]!r} of column '{col}' is not a number", source, lineno) from None
    return name, t, vals
