"""Tables of numbers in delimited text for the importers, read as a stream (numpy's C parser, bad lines skipped).

Used for Sensor Logger and phyphox files (a header line, then rows of
numbers separated by one delimiter) and for the record lines of
GetSensorData.  The text is read a chunk of lines at a time
(:class:`core.recording.TextLines`) into growing arrays
(:class:`ColumnBuffer`): memory holds the result and one chunk, never the
file's text or a Python object per row.  A row numpy refuses is parsed
again in Python to tell a bad line (named, skipped and counted under the
one rule of :func:`core.recording.skip_bad_lines`) from an optional empty
field.  Errors name the file and the line.
"""

from __future__ import annotations

import csv
import io
import re
from array import array

import numpy as np

from core.recording import MAX_BAD_LINES, RecordingError

_ROWCOL = re.compile(r"at row (\d+), column (\d+)")
_SHORT = re.compile(r"invalid column index -?\d+ at row (\d+) with (\d+) columns")
#: failures in one chunk after which its other rows are parsed in Python at once (buffers of different lengths
#: leave long runs of empty fields at the end of a phyphox file)
_DENSE_FAILURES = 16


class ColumnBuffer:
    """A growing ``(n, k)`` array of one dtype, appended a block of rows at a time.

    It lives in one :class:`array.array`, which grows in place: no Python
    object per row and no final concatenation (the peak is the array, not
    twice it).  :meth:`array` views it as numpy without a copy.
    """

    __slots__ = ("_a", "k", "dtype")

    _TYPECODES = {np.dtype(np.float64): "d", np.dtype(np.int64): "q", np.dtype(np.bool_): "B"}

    def __init__(self, k: int, dtype=np.float64):
        self.dtype = np.dtype(dtype)
        self._a = array(self._TYPECODES[self.dtype])
        self.k = k

    def append(self, rows: np.ndarray) -> None:
        rows = np.ascontiguousarray(rows, dtype=self.dtype)
        if rows.size:
            self._a.frombytes(memoryview(rows).cast("B"))

    def __len__(self) -> int:
        return len(self._a) // max(self.k, 1)

    def array(self) -> np.ndarray:
        """The rows as an ``(n, k)`` numpy array (a view of the buffer; the buffer cannot grow after this)."""
        if not self.k:
            return np.zeros((0, 0), dtype=self.dtype)
        return np.frombuffer(self._a, dtype=self.dtype).reshape(-1, self.k)


def number(s: str) -> float:
    """``float(s)`` for what numpy's parser reads as a number too (no ``1_000``, no non-ASCII digits)."""
    if "_" in s or not s.isascii():
        raise ValueError(s)
    return float(s)


def integer(s: str) -> int:
    """``int(s)`` for what numpy's parser reads as an int64 too."""
    if "_" in s or not s.isascii():
        raise ValueError(s)
    v = int(s)
    if not -2**63 <= v < 2**63:
        raise ValueError(s)
    return v


class BadRow(Exception):
    """A row that cannot be read (its message names the problem)."""


def parse_rows(rows: list[str], usecols: list[int], delimiter: str, slow, *, int_first: bool = False,
               max_bad: int = MAX_BAD_LINES + 1):
    """Rows of numbers: numpy's C parser, and ``slow(j)`` (Python) for each row it refuses.

    ``usecols``: the fields read (the first one int64 with ``int_first``).
    ``slow(j)`` returns ``(values, empty)`` for row ``j`` -- a float per
    field after the int, and which fields were empty -- or raises
    :class:`BadRow`.  Returns ``(ints or None, floats (n, m), empty (n, m)
    bool, keep (n,) bool, bad [(j, message)])``; rows not kept are the bad
    ones.  At most ``max_bad`` bad rows are looked for.
    """
    n = len(rows)
    m = len(usecols) - int_first
    ints = np.zeros(n, dtype=np.int64) if int_first else None
    floats = np.empty((n, m))
    empty = np.zeros((n, m), dtype=bool)
    keep = np.ones(n, dtype=bool)
    bad: list[tuple[int, str]] = []
    dtype = [("t", np.int64), ("v", np.float64, (m,))] if int_first else np.float64
    start = failures = 0

    def put(a: int, block) -> None:
        if int_first:
            ints[a:a + len(block)] = block["t"]
            floats[a:a + len(block)] = block["v"].reshape(len(block), m)
        else:
            floats[a:a + len(block)] = block

    def one(j: int) -> None:
        try:
            vals, emp = slow(j)
        except BadRow as e:
            keep[j] = False
            bad.append((j, str(e)))
            return
        if int_first:
            ints[j] = vals[0]
            vals = vals[1:]
        floats[j] = vals
        empty[j] = emp

    while start < n and len(bad) < max_bad:
        if failures >= _DENSE_FAILURES:
            for j in range(start, n):
                one(j)
                if len(bad) >= max_bad:
                    break
            break
        try:
            put(start, np.loadtxt(rows[start:] if start else rows, delimiter=delimiter, usecols=usecols, dtype=dtype,
                                  comments=None, ndmin=1 if int_first else 2, quotechar=None))
            break
        except ValueError as e:
            msg = str(e)
            m_short, m_rc = _SHORT.search(msg), _ROWCOL.search(msg)
            if m_short:  # numpy counts these rows from 1
                r = int(m_short.group(1)) - 1
            elif m_rc:
                r = int(m_rc.group(1))
            else:
                r = None
            if r is None or not 0 <= r < n - start:
                r = n - start  # no row named: every row in Python
                failures = _DENSE_FAILURES
                continue
            if r:
                put(start, np.loadtxt(rows[start:start + r], delimiter=delimiter, usecols=usecols, dtype=dtype,
                                      comments=None, ndmin=1 if int_first else 2, quotechar=None))
            one(start + r)
            start += r + 1
            failures += 1
    if len(bad) >= max_bad:  # the rows after the last bad one looked for were not parsed
        keep[bad[-1][0] + 1:] = False
    return ints, floats, empty, keep, bad


def fixed_rows(rows: list[str], usecols: list[int], delimiter: str | None, nfields: tuple[int, int], *,
               int_first: bool = True, names: list[str] | None = None):
    """Rows of one layout without a header: ``(ints or None, floats, kept, bad)``.

    A row must have ``nfields[0]`` to ``nfields[1]`` fields (``delimiter``
    ``None``: runs of whitespace) and numbers in the fields ``usecols`` (the
    first an int64 with ``int_first``); others are bad rows.  ``ints`` (n,)
    and ``floats`` (n, len(usecols) - int_first) hold the rows kept, in
    order; ``kept`` marks them among ``rows``; ``bad`` lists ``(row, message)``
    in row order (``names``: the fields' names for the messages).
    """
    n = len(rows)
    lo, hi = nfields
    if delimiter is None:
        have = np.fromiter((len(r.split()) for r in rows), dtype=np.int64, count=n)
    else:
        have = np.fromiter((r.count(delimiter) for r in rows), dtype=np.int64, count=n) + 1
    ok = (have >= lo) & (have <= hi)
    bad = [(int(j), f"missing fields: {lo} needed, found {int(have[j])}" if have[j] < lo else
            f"too many fields: at most {hi}, found {int(have[j])}") for j in np.flatnonzero(~ok)]
    idx = np.flatnonzero(ok)
    sub = rows if len(idx) == n else [rows[i] for i in idx]

    def slow(j):
        f = sub[j].split(delimiter)
        vals = []
        for k, c in enumerate(usecols):
            try:
                vals.append(integer(f[c]) if int_first and not k else number(f[c]))
            except ValueError:
                name = names[c] if names and c < len(names) else f"field {c + 1}"
                what = "an integer" if int_first and not k else "a number"
                raise BadRow(f"{name} is not {what}: {f[c][:40]!r}") from None
        return vals, [False] * (len(usecols) - int_first)

    ints, floats, _, keep, b = parse_rows(sub, usecols, delimiter, slow, int_first=int_first)
    bad += [(int(idx[j]), msg) for j, msg in b]
    bad.sort()
    kept = np.zeros(n, dtype=bool)
    kept[idx[keep]] = True
    return (ints[keep] if int_first else None), floats[keep], kept, bad


class Table:
    """A delimited text file of numbers: its header, then its rows read once, as a stream.

    ``text`` is a :class:`core.recording.TextLines` (or anything iterating
    ``(first line number, lines)`` with a ``tail``).  The header is the
    first line.  :attr:`blank` is true for a file of nothing but
    whitespace (no header).  Data lines are the non-blank lines after it;
    a last line that lacks its newline and has fewer fields than the header
    (a recording cut off mid-write) is dropped and reported in
    :attr:`dropped_tail` (its line number) -- with ``cut_tail`` any last
    line without its newline is (for apps that end every line with one: it
    may be cut inside its last number).  ``dialect(header, first data line)
    -> (delimiter, decimal_comma)`` may choose the dialect.
    """

    def __init__(self, text, where: str, delimiter: str = ",", decimal_comma: bool = False, dialect=None,
                 cut_tail: bool = False):
        self.where = where
        self.cut_tail = cut_tail
        self._text = text
        self._it = iter(text)
        self.dropped_tail: int | None = None
        #: bad lines met by :meth:`read` (errors naming their lines, in file order), and the data lines read
        self.bad: list[RecordingError] = []
        self.n_lines = 0
        complete: list[str] = []
        ended = False
        while len(complete) < 2:  # the header and, for the dialect, the first data line
            try:
                complete.extend(next(self._it)[1])
            except StopIteration:
                ended = True
                break
        view = complete + [text.tail] if ended else complete  # a text without newlines: its tail is a line too
        self.blank = not view[0].strip() and not self._rest_has_text(view)
        self.header: list[str] = []
        self._pending = (2, complete[1:]) if len(complete) > 1 else None
        if self.blank:
            return
        if not view[0].strip():
            raise RecordingError("empty file: expected a header line", where, 1)
        if dialect is not None:
            delimiter, decimal_comma = dialect(view[0], view[1] if len(view) > 1 else "")
        self.delimiter = delimiter
        self.decimal_comma = decimal_comma
        try:
            self.header = [h.strip().strip('"').strip() for h in _split_row(view[0], delimiter)]
        except csv.Error as e:
            raise RecordingError(f"header line: {e}", where, 1) from None

    def _rest_has_text(self, lines: list[str]) -> bool:
        if any(ln.strip() for ln in lines):
            return True
        for _, more in self._it:
            if any(ln.strip() for ln in more):
                return True
        return bool(self._text.tail.strip())

    def index(self, name: str) -> int | None:
        low = [h.lower() for h in self.header]
        return low.index(name.lower()) if name.lower() in low else None

    def require(self, names: list[str], what: str) -> list[int]:
        idx = []
        for n in names:
            i = self.index(n)
            if i is None:
                raise RecordingError(f"{what}: missing column '{n}' (header: {','.join(self.header)})",
                                     self.where, 1)
            idx.append(i)
        return idx

    def _chunks(self):
        """``(first line number, lines)`` of the data, the tail included when it is a whole line."""
        if self._pending is not None:
            yield self._pending
            self._pending = None
        yield from self._it
        tail = self._text.tail
        if tail and tail.strip() and self._text.tail_line > 1:
            if self.cut_tail or tail.count(self.delimiter) + 1 < len(self.header):
                self.dropped_tail = self._text.tail_line
            else:
                yield self._text.tail_line, [tail]

    def read(self, cols: list[tuple[int, str]], *, head_cols: list[int] = (), head_rows: int = 0,
             with_lines: bool = False, with_empty: bool = False) -> dict:
        """Read the rows once; ``cols`` are ``(column, mode)`` pairs, in the order of the result.

        Modes: ``"i"`` an int64 (at most one, first), ``"f"`` a number, ``"o"``
        an optional number (an empty or absent field is nan, marked in
        ``empty``).  A line whose ``"i"`` or ``"f"`` field is absent
        ("missing fields") or any field is not a number is a bad line: it is
        skipped and listed in :attr:`bad` (the reading stops past
        :data:`core.recording.MAX_BAD_LINES`; the caller applies
        :func:`core.recording.skip_bad_lines`).  ``head_cols`` are read
        leniently (anything else than a number is nan) for the first
        ``head_rows`` rows only.  Returns a dict: ``"t"`` (n,) int64 (with an
        ``"i"`` column), ``"v"`` (n, number of other columns) float64,
        ``"head"`` (at most ``head_rows``, len(head_cols)), ``"line"`` (n,)
        file line numbers (``with_lines``), ``"empty"`` (n, ...) bool
        (``with_empty``).
        """
        int_first = bool(cols) and cols[0][1] == "i"
        idx = [c for c, _ in cols]
        modes = [mo for _, mo in cols]
        nf = len(cols) - int_first
        out_t = ColumnBuffer(1, np.int64) if int_first else None
        out_v = ColumnBuffer(nf)
        out_line = ColumnBuffer(1, np.int64) if with_lines else None
        out_empty = ColumnBuffer(nf, np.bool_) if with_empty else None
        head = ColumnBuffer(len(head_cols))
        strict_max = max((c for c, mo in cols if mo in "if"), default=-1)
        delim = self.delimiter
        names = self.header
        for first_no, lines in self._chunks():
            nonblank = [j for j, ln in enumerate(lines) if ln and not ln.isspace()]
            if len(nonblank) != len(lines):
                lines = [lines[j] for j in nonblank]
            if not lines:
                continue
            if any('"' in ln for ln in lines):  # quoted fields: let the csv module split them, then re-join
                lines = [_unquote(ln, delim) if '"' in ln else ln for ln in lines]
            if self.decimal_comma and delim != ",":
                lines = [ln.replace(",", ".") for ln in lines]
            self.n_lines += len(lines)
            use_head = len(head) < head_rows
            usecols = idx + (list(head_cols) if use_head else [])

            def slow(j, lines=lines, use_head=use_head):
                f = lines[j].split(delim)
                if strict_max >= len(f):
                    raise BadRow(f"missing fields: the header has {len(names)} columns, this line {len(f)}")
                vals, emp = [], []
                for c, mo in zip(idx, modes):
                    s = f[c] if c < len(f) else ""
                    if mo == "o" and not s.strip():
                        vals.append(np.nan)
                        emp.append(True)
                        continue
                    try:
                        vals.append(integer(s) if mo == "i" else number(s))
                    except ValueError:
                        what = "an integer" if mo == "i" else "a number"
                        name = names[c] if c < len(names) else f"#{c + 1}"
                        raise BadRow(f"column '{name}' is not {what}: {s!r}") from None
                    if mo != "i":
                        emp.append(False)
                if use_head:
                    for c in head_cols:
                        try:
                            vals.append(number(f[c]) if c < len(f) else np.nan)
                        except ValueError:
                            vals.append(np.nan)
                        emp.append(False)
                return vals, emp

            ints, floats, empty, keep, bad = parse_rows(lines, usecols, delim, slow, int_first=int_first,
                                                        max_bad=MAX_BAD_LINES + 1 - len(self.bad))
            for j, msg in bad:
                self.bad.append(RecordingError(msg, self.where, first_no + nonblank[j]))
            allk = bool(keep.all())
            if int_first:
                out_t.append(ints if allk else ints[keep])
            out_v.append(floats[:, :nf] if allk else floats[keep, :nf])
            if use_head:
                h = floats[:, nf:] if allk else floats[keep, nf:]
                head.append(h[:head_rows - len(head)])
            if with_lines:
                ln = np.asarray(nonblank, dtype=np.int64) + first_no
                out_line.append(ln if allk else ln[keep])
            if with_empty:
                out_empty.append(empty[:, :nf] if allk else empty[keep, :nf])
            if len(self.bad) > MAX_BAD_LINES:
                break
        res = {"v": out_v.array(), "head": head.array()}
        if int_first:
            res["t"] = out_t.array()[:, 0]
        if with_lines:
            res["line"] = out_line.array()[:, 0]
        if with_empty:
            res["empty"] = out_empty.array()
        return res


def _split_row(line: str, delimiter: str) -> list[str]:
    return next(csv.reader([line], delimiter=delimiter), [])


def _unquote(line: str, delimiter: str) -> str:
    """A line with quoted fields, re-joined without the quotes (as it is, if the csv module cannot split it)."""
    try:
        return delimiter.join(_split_row(line, delimiter))
    except csv.Error:
        return line


def csv_rows(text: str, where: str, delimiter: str = ",") -> list[list[str]]:
    """The rows of a small CSV text (a metadata file); what the csv module cannot split is a RecordingError."""
    try:
        return list(csv.reader(io.StringIO(text), delimiter=delimiter))
    except csv.Error as e:
        raise RecordingError(f"not readable as CSV: {e}", where) from None
