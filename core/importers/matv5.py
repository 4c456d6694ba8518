"""A small reader of MATLAB level-5 MAT-files (numpy + zlib only: :mod:`core` runs on the phone, without scipy).

It reads the subset that numeric data files use -- what ``scipy.io.savemat``
and MATLAB's ``save -v7`` write for plain matrices -- and says so clearly for
anything else.

The format (MathWorks, "MAT-File Format", level 5)
=================================================
* A 128-byte header: 116 bytes of text (``MATLAB 5.0 MAT-file, ...``), 8
  bytes of subsystem offset, a 2-byte version (0x0100) and the endian
  indicator ``IM`` (little-endian file) or ``MI`` (big-endian).
* Then data elements, each a tag and its data.  A tag is 8 bytes, ``type``
  (uint32) and ``size`` in bytes (uint32), the data padded to 8 bytes; or, for
  at most 4 bytes of data, a *small* element: ``size`` in the upper 16 bits of
  the first uint32, ``type`` in the lower, the data in the next 4 bytes.
* A top-level element is ``miMATRIX`` (14), one variable, or ``miCOMPRESSED``
  (15): zlib data holding one ``miMATRIX`` element.
* A ``miMATRIX`` holds sub-elements: array flags (``miUINT32`` x 2: the class
  in the low byte of the first, the complex flag 0x0800, the logical flag
  0x0200), dimensions (``miINT32``), the name (``miINT8`` text), then the real
  part (and for a complex array the imaginary part) in any numeric data type
  (``miINT8`` 1 ... ``miDOUBLE`` 9, ``miINT64`` 12, ``miUINT64`` 13), stored
  column-major (Fortran order).  Character arrays (``mxCHAR_CLASS``, 4) carry
  ``miUTF8``/``miUTF16``/``miUINT16``/``miUINT8`` codes.

Read here: real numeric and logical arrays of any dimensions (returned as
numpy arrays of the class's dtype, shaped as in MATLAB) and character arrays
(returned as ``str``, rows joined by newlines).  Cell arrays, structures,
objects, sparse and complex arrays and function handles are *skipped*, their
names listed in :attr:`MatFile.skipped` (a caller asking for one gets a
clear error) -- unless ``read_mat(..., objects=True)``, which reads cell
arrays, structures, complex arrays and opaque (MATLAB class) objects too
(:func:`value_of`, :func:`values_in`; :mod:`core.importers.matlabmobile`
decodes the class objects of a MATLAB Mobile log from them).  A level-4 or HDF5-based (``-v7.3``) file is refused.

Streaming and limits
====================
The file (gzip by content, as every reader here) is read element by element:
memory holds the variables read and one element's bytes, never the whole
file.  Every element's size is checked against what is left of the
``max_uncompressed_bytes`` budget *before* it is read, and a ``miCOMPRESSED``
element is inflated with the same budget, so a small file cannot claim or
inflate into more.  Every problem is a :class:`core.recording.RecordingError`
naming the file and the variable.
"""

from __future__ import annotations

import zlib

import numpy as np

from core.recording import MAX_UNCOMPRESSED_BYTES, ByteChunks, RecordingError, over_limit_error

HEADER_BYTES = 128

MI_INT8, MI_UINT8, MI_INT16, MI_UINT16, MI_INT32, MI_UINT32 = 1, 2, 3, 4, 5, 6
MI_SINGLE, MI_DOUBLE, MI_INT64, MI_UINT64 = 7, 9, 12, 13
MI_MATRIX, MI_COMPRESSED, MI_UTF8, MI_UTF16, MI_UTF32 = 14, 15, 16, 17, 18

#: numeric data types of the data elements -> numpy dtype (byte order added per file)
MI_DTYPES = {MI_INT8: "i1", MI_UINT8: "u1", MI_INT16: "i2", MI_UINT16: "u2", MI_INT32: "i4", MI_UINT32: "u4",
             MI_SINGLE: "f4", MI_DOUBLE: "f8", MI_INT64: "i8", MI_UINT64: "u8"}

MX_CELL, MX_STRUCT, MX_OBJECT, MX_CHAR, MX_SPARSE, MX_OPAQUE = 1, 2, 3, 4, 5, 17
#: numeric array classes -> the numpy dtype of the array returned
MX_DTYPES = {6: np.float64, 7: np.float32, 8: np.int8, 9: np.uint8, 10: np.int16, 11: np.uint16, 12: np.int32,
             13: np.uint32, 14: np.int64, 15: np.uint64}
MX_NAMES = {MX_CELL: "cell array", MX_STRUCT: "structure", MX_OBJECT: "object", MX_SPARSE: "sparse array",
            16: "function handle", 17: "opaque object"}
FLAG_COMPLEX = 0x0800
FLAG_LOGICAL = 0x0200

#: a MAT-file's first bytes: the text header every level-5 file starts with
TEXT_MAGIC = b"MATLAB 5.0 MAT-file"


def looks_like(head: bytes) -> bool:
    """True if ``head`` (the first bytes, decompressed) is a level-5 MAT-file's header."""
    return len(head) >= HEADER_BYTES and head.startswith(TEXT_MAGIC) and head[126:128] in (b"IM", b"MI")


def level5_header(head: bytes) -> bool:
    """True if ``head`` has a level-5 header's binary end (version 0x0100 and ``IM``/``MI`` at bytes 124-127)
    whatever its text: some writers put their own there (Qualisys Track Manager: ``QTM_ver 2.10 ...``).  Only
    :func:`read_mat` accepts such a file (it is asked to read a MAT-file); detection keeps :func:`looks_like`."""
    return (len(head) >= HEADER_BYTES and head[126:128] in (b"IM", b"MI")
            and head[124:126] == (b"\x00\x01" if head[126:128] == b"IM" else b"\x01\x00"))


class _Reader:
    """Exact reads of ``n`` bytes from a stream of chunks (at most ``budget`` bytes in all)."""

    def __init__(self, chunks, source: str):
        self.it = iter(chunks)
        self.source = source
        self.buf = bytearray()
        self.pos = 0  # bytes consumed so far (for messages)

    def read(self, n: int, what: str) -> bytes:
        while len(self.buf) < n:
            more = next(self.it, None)
            if more is None:
                raise RecordingError(f"MAT-file cut off in {what} (byte {self.pos + len(self.buf)} of {n} "
                                     "wanted from there)", self.source)
            self.buf += more
        out = bytes(self.buf[:n])
        del self.buf[:n]
        self.pos += n
        return out

    def at_end(self) -> bool:
        while not self.buf:
            more = next(self.it, None)
            if more is None:
                return True
            self.buf += more
        return False


class MatFile:
    """The variables of a MAT-file: ``mat["imu"]`` (numpy array or str), ``"imu" in mat``, :meth:`names`.

    ``skipped``: names of variables of a kind this reader does not read
    (cell arrays, structures, sparse or complex arrays, ...) with the kind.
    ``all_names``: every variable's name in file order (read or not).
    """

    def __init__(self, source: str, header: str, variables: dict, skipped: dict, all_names: list[str]):
        self.source = source
        self.header = header
        self.variables = variables
        self.skipped = skipped
        self.all_names = all_names

    def names(self) -> list[str]:
        return list(self.variables)

    def __contains__(self, name: str) -> bool:
        return name in self.variables

    def __getitem__(self, name: str):
        if name in self.variables:
            return self.variables[name]
        if name in self.skipped:
            raise RecordingError(f"MAT-file variable {name!r} is a {self.skipped[name]}, which this reader does "
                                 "not read", self.source)
        raise RecordingError(f"MAT-file has no variable {name!r} (it has: {', '.join(self.variables) or 'none'})",
                             self.source)


def read_mat(f, source: str, *, max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES,
             only: set[str] | None = None, objects: bool = False) -> MatFile:
    """Read a level-5 MAT-file from the binary file object ``f`` (gzip by content); see the module doc.

    ``only``: read these variables and skip the others' data (their size is
    still checked against the budget).  ``objects``: also read cell arrays,
    structures and opaque objects (:func:`value_of`) instead of skipping them.
    """
    limit = max_uncompressed_bytes
    chunks = ByteChunks(f, source, limit=limit)
    r = _Reader(chunks, source)
    head = r.read(HEADER_BYTES, "the 128-byte header") if not r.at_end() else b""
    if not (looks_like(head) or level5_header(head)):
        if head.startswith(b"MATLAB 7.3 MAT-file") or head[:4] == b"\x89HDF":
            raise RecordingError("a MAT-file of version 7.3 (HDF5): not read here (save with -v7)", source)
        raise RecordingError("not a level-5 MAT-file (no 'MATLAB 5.0 MAT-file' header ending in IM or MI)", source)
    order = "<" if head[126:128] == b"IM" else ">"
    variables: dict = {}
    skipped: dict = {}
    seen: list[str] = []
    used = HEADER_BYTES
    while not r.at_end():
        typ, size = _tag(r.read(8, "a data element's tag"), order)
        padded = size + (-size) % 8 if typ != MI_COMPRESSED else size
        used += 8 + padded
        if limit is not None and used > limit:
            raise over_limit_error("the MAT-file's data", limit, source, size=used)
        if typ not in (MI_MATRIX, MI_COMPRESSED):
            r.read(padded, f"a data element of type {typ}")  # top-level elements of other types: nothing to read
            continue
        body = r.read(padded, "a variable")[:size]
        if typ == MI_COMPRESSED:
            body = _inflate(body, source, None if limit is None else limit - used + size)
            if len(body) < 8:
                raise RecordingError("MAT-file: a compressed element holds no data element", source)
            inner, isize = _tag(body[:8], order)
            if inner != MI_MATRIX:
                continue
            body = body[8:8 + isize]
        _matrix(body, order, source, variables, skipped, only, seen, objects)
    return MatFile(source, head[:116].rstrip(b" \x00").decode("latin-1"), variables, skipped, seen)


def _inflate(data: bytes, source: str, budget: int | None) -> bytes:
    d = zlib.decompressobj()
    try:
        out = d.decompress(data, budget + 1 if budget is not None else 0)
    except zlib.error as e:
        raise RecordingError(f"MAT-file: corrupt compressed element ({e})", source) from None
    if budget is not None and (len(out) > budget or d.unconsumed_tail):
        raise over_limit_error("a compressed MAT-file element", budget, source)
    return out


def _tag(b: bytes, order: str) -> tuple[int, int]:
    a, size = np.frombuffer(b, dtype=order + "u4").tolist()
    return int(a), int(size)


def _sub(body: bytes, pos: int, order: str, source: str, name: str) -> tuple[int, bytes, int]:
    """One sub-element of a matrix at ``pos``: ``(type, data, next pos)`` (small elements too)."""
    if pos + 8 > len(body):
        raise RecordingError(f"MAT-file variable {name or '?'}: cut off inside its elements", source)
    a, size = _tag(body[pos:pos + 8], order)
    if a >> 16:  # small data element: size in the upper 16 bits, data in the next 4 bytes
        n = a >> 16
        if n > 4:
            raise RecordingError(f"MAT-file variable {name or '?'}: bad small element of {n} bytes", source)
        return a & 0xFFFF, body[pos + 4:pos + 4 + n], pos + 8
    end = pos + 8 + size
    if end > len(body):
        raise RecordingError(f"MAT-file variable {name or '?'}: an element of {size} bytes runs past its end",
                             source)
    return a, body[pos + 8:end], end + (-size) % 8


def _numbers(typ: int, data: bytes, order: str, source: str, name: str) -> np.ndarray:
    dt = MI_DTYPES.get(typ)
    if dt is None:
        raise RecordingError(f"MAT-file variable {name!r}: data of type {typ}, not a numeric type", source)
    dt = np.dtype(order + dt)
    if len(data) % dt.itemsize:
        raise RecordingError(f"MAT-file variable {name!r}: {len(data)} bytes is not a whole number of "
                             f"{dt.itemsize}-byte values", source)
    return np.frombuffer(data, dtype=dt)


def _flags(body: bytes, order: str, source: str) -> tuple[int, int]:
    """A matrix's first word of array flags and the position after them."""
    typ, flags, pos = _sub(body, 0, order, source, "")
    if typ != MI_UINT32 or len(flags) < 8:
        raise RecordingError("MAT-file: a variable without its array flags", source)
    return int(np.frombuffer(flags[:4], dtype=order + "u4")[0]), pos


def _matrix(body: bytes, order: str, source: str, variables: dict, skipped: dict, only, seen: list,
            objects: bool = False) -> None:
    f0, pos = _flags(body, order, source)
    cls = f0 & 0xFF
    if cls == MX_OPAQUE:  # flags, name, type name, class name, data: no dimensions
        name = _sub(body, pos, order, source, "")[1].decode("latin-1")
        seen.append(name)
        if only is None or name in only:
            if objects:
                variables[name] = value_of(body, order, source)
            else:
                skipped[name] = MX_NAMES[cls]
        return
    typ, dims_b, pos = _sub(body, pos, order, source, "")
    if typ != MI_INT32:
        raise RecordingError("MAT-file: a variable without its dimensions", source)
    dims = [int(x) for x in _numbers(MI_INT32, dims_b, order, source, "")]
    typ, name_b, pos = _sub(body, pos, order, source, "")
    name = name_b.decode("latin-1")
    seen.append(name)
    if only is not None and name not in only:
        return
    if objects and cls in (MX_CELL, MX_STRUCT, MX_OBJECT):
        variables[name] = value_of(body, order, source)
        return
    if cls in MX_NAMES:
        skipped[name] = MX_NAMES[cls]
        return
    if f0 & FLAG_COMPLEX:
        skipped[name] = "complex array"
        return
    if any(d < 0 for d in dims):
        raise RecordingError(f"MAT-file variable {name!r}: negative dimensions {dims}", source)
    n = int(np.prod(dims)) if dims else 0
    typ, data, pos = _sub(body, pos, order, source, name)
    if cls == MX_CHAR:
        variables[name] = _chars(typ, data, dims, order, source, name)
        return
    if cls not in MX_DTYPES:
        skipped[name] = f"array of class {cls}"
        return
    v = _numbers(typ, data, order, source, name)
    if len(v) != n:
        raise RecordingError(f"MAT-file variable {name!r}: {len(v)} values for dimensions "
                             f"{'x'.join(map(str, dims))}", source)
    out = v.astype(np.bool_ if f0 & FLAG_LOGICAL else MX_DTYPES[cls])
    variables[name] = out.reshape(dims, order="F") if dims else out


def _chars(typ: int, data: bytes, dims: list[int], order: str, source: str, name: str) -> str:
    if typ in (MI_UTF8, MI_INT8, MI_UINT8):
        text = data.decode("utf-8", errors="replace")
    elif typ in (MI_UTF16, MI_UINT16):
        text = data.decode("utf-16-be" if order == ">" else "utf-16-le", errors="replace")
    else:
        raise RecordingError(f"MAT-file variable {name!r}: characters of data type {typ}", source)
    rows = dims[0] if dims else 0
    n = int(np.prod(dims)) if dims else 0
    if rows > 1 and len(text) == n:  # column-major: character k of row i is text[k * rows + i]
        text = "\n".join(text[i::rows] for i in range(rows))
    return text


class MatOpaque:
    """An opaque object of a MAT-file (MATLAB's ``MCOS`` class objects): its type and class names and its data
    (for an object in a variable, the ``uint32`` reference into the file's subsystem data)."""

    __slots__ = ("type_name", "class_name", "data")

    def __init__(self, type_name: str, class_name: str, data):
        self.type_name, self.class_name, self.data = type_name, class_name, data


#: nesting deeper than this is refused (a damaged file cannot recurse without end)
MAX_NESTING = 32


def value_of(body: bytes, order: str, source: str, depth: int = 0):
    """The value of one ``miMATRIX`` element's body, any class: numeric and logical arrays (numpy, complex ones
    complex), text (``str``), a cell array (a list in MATLAB's column-major order; an empty element ``None``),
    a structure or an object (a ``dict`` of its fields for one element, a list of dicts for several) and an opaque
    object (:class:`MatOpaque`).  Sparse arrays and function handles are a :class:`RecordingError`."""
    if depth > MAX_NESTING:
        raise RecordingError(f"MAT-file: values nested more than {MAX_NESTING} deep", source)
    f0, pos = _flags(body, order, source)
    cls = f0 & 0xFF
    if cls == MX_OPAQUE:
        parts = []
        for _ in range(3):  # name, type name, class name
            _, b, pos = _sub(body, pos, order, source, "")
            parts.append(b.decode("latin-1"))
        typ, inner, pos = _sub(body, pos, order, source, parts[0])
        data = value_of(inner, order, source, depth + 1) if typ == MI_MATRIX and inner else None
        return MatOpaque(parts[1], parts[2], data)
    typ, dims_b, pos = _sub(body, pos, order, source, "")
    if typ != MI_INT32:
        raise RecordingError("MAT-file: a value without its dimensions", source)
    dims = [int(x) for x in _numbers(MI_INT32, dims_b, order, source, "")]
    if any(d < 0 for d in dims):
        raise RecordingError(f"MAT-file: negative dimensions {dims}", source)
    _, name_b, pos = _sub(body, pos, order, source, "")
    name = name_b.decode("latin-1")
    n = int(np.prod(dims)) if dims else 0
    if cls == MX_CELL:
        items = []
        for _ in range(n):
            typ, el, pos = _sub(body, pos, order, source, name)
            items.append(value_of(el, order, source, depth + 1) if typ == MI_MATRIX and el else None)
        return items
    if cls in (MX_STRUCT, MX_OBJECT):
        if cls == MX_OBJECT:
            pos = _sub(body, pos, order, source, name)[2]  # the class name
        _, fl, pos = _sub(body, pos, order, source, name)
        width = int(_numbers(MI_INT32, fl, order, source, name)[0]) if fl else 0
        _, raw, pos = _sub(body, pos, order, source, name)
        fields = [raw[i:i + width].split(b"\0")[0].decode("latin-1") for i in range(0, len(raw), width)] if width else []
        recs = []
        for _ in range(n):
            rec = {}
            for fname in fields:
                typ, el, pos = _sub(body, pos, order, source, name)
                rec[fname] = value_of(el, order, source, depth + 1) if typ == MI_MATRIX and el else None
            recs.append(rec)
        return recs[0] if n == 1 else recs
    if cls in MX_NAMES or cls not in MX_DTYPES and cls != MX_CHAR:
        raise RecordingError(f"MAT-file value {name or '?'}: a {MX_NAMES.get(cls, f'class {cls}')}, not read here",
                             source)
    typ, data, pos = _sub(body, pos, order, source, name)
    if cls == MX_CHAR:
        return _chars(typ, data, dims, order, source, name)
    v = _numbers(typ, data, order, source, name) if data else np.zeros(0)
    if f0 & FLAG_COMPLEX:
        typ, im, pos = _sub(body, pos, order, source, name)
        v = v.astype(np.float64) + 1j * (_numbers(typ, im, order, source, name) if im else np.zeros(0))
    if len(v) != n:
        raise RecordingError(f"MAT-file value {name or '?'}: {len(v)} values for dimensions "
                             f"{'x'.join(map(str, dims))}", source)
    if not f0 & FLAG_COMPLEX:
        v = v.astype(np.bool_ if f0 & FLAG_LOGICAL else MX_DTYPES[cls])
    return v.reshape(dims, order="F") if dims else v


def values_in(raw: bytes, pos: int, order: str, source: str) -> list:
    """The values (:func:`value_of`) of the ``miMATRIX`` / ``miCOMPRESSED`` elements of ``raw`` from ``pos`` on
    (a MAT stream without the file header: a MAT-file's subsystem data after its 8 bytes of version and order)."""
    out = []
    while pos + 8 <= len(raw):
        typ, body, pos = _sub(raw, pos, order, source, "subsystem data")
        if typ == MI_COMPRESSED:
            body = _inflate(body, source, MAX_UNCOMPRESSED_BYTES)
            typ, size = _tag(body[:8], order) if len(body) >= 8 else (0, 0)
            body = body[8:8 + size]
        if typ == MI_MATRIX and body:
            out.append(value_of(body, order, source))
    return out
