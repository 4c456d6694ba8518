"""A small strict CSV table reader for the importers (numbers only, numpy's C parser).

Used for Sensor Logger and phyphox files: a header line, then rows of
numbers separated by one delimiter.  Errors name the file and the line.
"""

from __future__ import annotations

import csv
import io
import re

import numpy as np

from core.recording import RecordingError

_ROWCOL = re.compile(r"at row (\d+), column (\d+)")
_SHORT = re.compile(r"invalid column index -?\d+ at row (\d+) with (\d+) columns")


class Table:
    """The header and data lines of a delimited text file.

    ``lines`` are the non-empty data lines; :meth:`lineno` gives their 1-based
    line numbers in the file (for messages).  A last line that lacks its newline
    and has fewer fields than the header (a recording cut off mid-write) is
    dropped and reported in ``dropped_tail``.
    """

    def __init__(self, text: str, where: str, delimiter: str = ",", decimal_comma: bool = False):
        self.where = where
        self.delimiter = delimiter
        raw = text.split("\n")
        if not raw or not raw[0].strip():
            raise RecordingError("empty file: expected a header line", where, 1)
        self.header = [h.strip().strip('"').strip() for h in _split_row(raw[0], delimiter)]
        body = text[len(raw[0]):]
        self._raw = raw
        lines = [ln for ln in raw[1:] if ln and not ln.isspace()]
        self._blank_lines = len(lines) != len(raw) - 1 - (raw[-1] == "")
        if '"' in body:
            # quoted fields: let the csv module split them, then re-join unquoted
            lines = [delimiter.join(row) for row in csv.reader(io.StringIO("\n".join(lines)), delimiter=delimiter)]
        if decimal_comma and delimiter != ",":
            lines = [ln.replace(",", ".") for ln in lines]
        self.dropped_tail = None
        if lines and not text.endswith("\n") and lines[-1].count(delimiter) + 1 < len(self.header):
            self.dropped_tail = self.lineno(len(lines) - 1)
            lines.pop()
        self.lines = lines
        self._counts = None
        #: cells read as nan because the field was empty or absent (set by :meth:`columns`)
        self.empty = np.zeros((0, 0), dtype=bool)

    def lineno(self, j: int) -> int:
        """1-based line number in the file of data line ``j``."""
        if not self._blank_lines:
            return j + 2
        k = -1
        for i in range(1, len(self._raw)):
            ln = self._raw[i]
            if ln and not ln.isspace():
                k += 1
                if k == j:
                    return i + 1
        return len(self._raw)

    def __len__(self) -> int:
        return len(self.lines)

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

    def check_widths(self, needed: int) -> None:
        """Every data line must have at least ``needed`` fields."""
        if self._counts is None:
            self._counts = np.fromiter(map(lambda ln, d=self.delimiter: ln.count(d), self.lines), dtype=np.int64,
                                       count=len(self.lines))
        counts = self._counts
        short = np.flatnonzero(counts + 1 < needed)
        if len(short):
            j = int(short[0])
            raise RecordingError(f"missing fields: the header has {len(self.header)} columns, this line "
                                 f"{int(counts[j]) + 1}", self.where, self.lineno(j))

    def columns(self, idx: list[int], dtype=np.float64, empty_ok: bool = False,
                max_rows: int | None = None) -> np.ndarray:
        """Columns ``idx`` as an (n, len(idx)) array; non-numbers are a :class:`RecordingError`.

        With ``empty_ok`` an empty or absent field (a short line) reads as nan
        (optional values; phyphox buffers of different lengths) and
        :attr:`empty` marks those cells; otherwise a short line is a "missing
        fields" error.  ``max_rows`` reads only the first rows.
        """
        n = len(self.lines) if max_rows is None else min(max_rows, len(self.lines))
        self.empty = np.zeros((n, len(idx)), dtype=bool)
        if n == 0:
            return np.zeros((0, len(idx)), dtype=dtype)
        try:
            return np.loadtxt(self.lines if n == len(self.lines) else self.lines[:n], delimiter=self.delimiter,
                              usecols=idx, dtype=dtype, comments=None, ndmin=2, quotechar=None)
        except ValueError as e:
            if empty_ok and dtype is np.float64:
                return self._columns_slow(idx, n)
            m = _SHORT.search(str(e))
            if m:  # a line with fewer fields than the header (numpy counts these rows from 1)
                j = int(m.group(1)) - 1
                raise RecordingError(f"missing fields: the header has {len(self.header)} columns, this line "
                                     f"{m.group(2)}", self.where, self.lineno(j)) from None
            m = _ROWCOL.search(str(e))  # rows from 0, file columns from 1
            if m:
                j = int(m.group(1))
                c = int(m.group(2)) - 1
                f = self.lines[j].split(self.delimiter)
                raise self._bad(j, c, f[c] if c < len(f) else "", dtype) from None
            raise RecordingError(f"cannot parse numbers: {e}", self.where) from None

    def _columns_slow(self, idx: list[int], n: int) -> np.ndarray:
        out = np.empty((n, len(idx)))
        for j, ln in enumerate(self.lines[:n]):
            f = ln.split(self.delimiter)
            for k, c in enumerate(idx):
                s = f[c].strip() if c < len(f) else ""
                if not s:
                    out[j, k] = np.nan
                    self.empty[j, k] = True
                    continue
                try:
                    out[j, k] = float(s)
                except ValueError:
                    raise self._bad(j, c, s) from None
        return out

    def _bad(self, j: int, c: int, value: str, dtype=np.float64) -> RecordingError:
        what = "an integer" if dtype is np.int64 else "a number"
        name = self.header[c] if c < len(self.header) else f"#{c + 1}"
        return RecordingError(f"column '{name}' is not {what}: {value!r}", self.where, self.lineno(j))


def _split_row(line: str, delimiter: str) -> list[str]:
    return next(csv.reader([line], delimiter=delimiter))
