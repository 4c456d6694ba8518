"""Reader for XSens text exports as in the IPOL healthy-gait dataset (Voisard et al., IPOL 2023).

Format
======
Text (here also gzip): a line giving the rate, a header line, then one
sample a line, whitespace- (tab-) separated::

    Acquisition frequency: 100 Hz
    PacketCounter	Acc_X	Acc_Y	Acc_Z	Gyr_X	Gyr_Y	Gyr_Z	Mag_X	Mag_Y	Mag_Z
    0.0	8.225546	0.091094	5.899778	-0.003527	0.005281	0.000665	-0.289795	0.073486	-0.801758

Lines before the header that start with ``//`` (XSens MT Manager's
comments) are skipped.  Columns found by name: ``PacketCounter`` and
``Acc_X/Y/Z`` required, ``Gyr_*`` and ``Mag_*`` read when present.

* time: ``t_ns = PacketCounter * 1e9 / rate`` (the sensors sample at the
  acquisition frequency; 10 ms at 100 Hz).  Dropped packets stay gaps.  The
  XSens counter is 16 bits: a drop of more than half its range is a wrap
  and counts on (``metadata["counter_wraps"]``).  Absolute time unknown.
* ``Acc`` m/s^2 (gravity included) and ``Gyr`` rad/s: copied.  XSens sensor
  axes, not the Android device axes.
* ``Mag`` is in XSens normalised units (1 = the field where the sensor was
  calibrated): scaled by the nominal :data:`NOMINAL_FIELD_UT` to look like
  microtesla -- good for relative headings, not an absolute field.

A set of sensors of one trial
=============================
IPOL names a trial's three files ``<trial>_lb``, ``<trial>_lf``, ``<trial>_rf``
(lower back at the 5th lumbar vertebra, left foot, right foot; ``.txt`` or
``.txt.gz``).  Reading the lower-back file reads the trial: the lower back
is the primary device (``acc``, ``gyro``, ``mag``; ``device["placement"] =
"waist"``, the place of a belt-worn phone), each foot file found beside it
becomes the device ``left_foot`` / ``right_foot`` (``acc@left_foot``,
``gyro@right_foot``, ... of :mod:`core.foot.devices`, on the same
PacketCounter clock: the Awinda station synchronises them), described in
``metadata["devices"]``.  A foot file whose lower-back file is beside it is
part of that trial (:func:`trial_primary` names it; the format detection
points there); a foot file alone is read as the primary device (placement
"left foot" / "right foot").  Any other single XSens file is read as one
device without a placement.

A line with a field that is not a number or a number of fields other than
the header's is a bad line: skipped and counted, or, past 100 or 1 % of the
lines, a :class:`RecordingError` naming the first.
"""

from __future__ import annotations

import os
import re
import warnings

import numpy as np

from core.conventions import ACC, GYRO, MAG
from core.foot.devices import device_stream
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import feed_lines, finish, head_lines, open_text
from core.importers._csv import ColumnBuffer, fixed_rows

FORMAT = "xsens"

#: XSens normalised magnetic units -> uT (about the total field in western Europe; headings only)
NOMINAL_FIELD_UT = 47.0
COUNTER = "PacketCounter"
GROUPS = {ACC: ("Acc_X", "Acc_Y", "Acc_Z"), GYRO: ("Gyr_X", "Gyr_Y", "Gyr_Z"), MAG: ("Mag_X", "Mag_Y", "Mag_Z")}
COUNTER_RANGE = 1 << 16

_RATE = re.compile(r"^\s*(?://\s*)?(?:Acquisition frequency|Update Rate|Sample ?rate)\s*:\s*([0-9.]+)\s*Hz",
                   re.I)
#: IPOL's file names: <trial>_<sensor>.txt[.gz]
_IPOL_NAME = re.compile(r"^(?P<trial>.+)_(?P<part>lb|lf|rf)\.txt(?:\.gz)?$")
#: IPOL sensor suffix -> (device name, placement words)
IPOL_PARTS = {"lb": ("", "waist"), "lf": ("left_foot", "left foot"), "rf": ("right_foot", "right foot")}


def looks_like(head: str) -> bool:
    """The rate line (or ``//`` comments) and a whitespace-separated header naming ``PacketCounter`` and
    ``Acc_X/Y/Z``."""
    for line in head_lines(head, 12):
        s = line.strip()
        if s.startswith("//") or _RATE.match(s):
            continue
        names = s.split()
        return COUNTER in names and all(c in names for c in GROUPS[ACC])
    return False


def _ipol_parts(path: str) -> tuple[str, str] | None:
    m = _IPOL_NAME.match(os.path.basename(path))
    return (m.group("trial"), m.group("part")) if m else None


def _sibling(path: str, part: str) -> str | None:
    trial, own = _ipol_parts(path)
    folder = os.path.dirname(path)
    base = os.path.basename(path)
    ext = base[len(f"{trial}_{own}"):]
    for e in (ext, ".txt.gz", ".txt"):
        p = os.path.join(folder, f"{trial}_{part}{e}")
        if os.path.isfile(p):
            return p
    return None


def trial_primary(path: str) -> tuple[str, str] | None:
    """For an IPOL foot file whose lower-back file is beside it: ``(that file, the foot's device name)``.

    The lower-back file reads the whole trial (the foot is its device ``left_foot`` or ``right_foot``).
    """
    parts = _ipol_parts(str(path))
    if parts is None or parts[1] == "lb":
        return None
    primary = _sibling(str(path), "lb")
    return (primary, IPOL_PARTS[parts[1]][0]) if primary is not None else None


def read_xsens(path: str, *, warn: bool = True, with_siblings: bool = True,
               max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read an XSens text export (plain or gzip) into a :class:`Recording` (see the module doc).

    An IPOL lower-back file also reads the trial's foot files beside it
    (``with_siblings=False``: the one file only).  Every file is streamed a
    chunk of lines at a time; a gzip stream inflating to over
    ``max_uncompressed_bytes`` is refused while it is read.
    """
    path = str(path)
    repairs: list[str] = []
    parts = _ipol_parts(path)
    t_ns, values, info = _read_one(path, repairs, max_uncompressed_bytes)
    streams = {k: _stream(k, "", t_ns, values[k]) for k in values}
    device = {"model": "XSens MTw Awinda" if parts else "XSens", "axes": "XSens sensor axes, not Android device axes"}
    meta: dict = {"source_format": FORMAT, "app": "XSens text export", "rate_hz": info["rate_hz"],
                  "time_base": f"t_ns = PacketCounter * 1e9 / {info['rate_hz']:g} Hz (the acquisition frequency); "
                               "absolute time unknown"}
    if info["wraps"]:
        meta["counter_wraps"] = info["wraps"]
    if parts is not None:
        device["placement"] = IPOL_PARTS[parts[1]][1]
        meta["trial"] = parts[0]
        if parts[1] == "lb" and with_siblings:
            devices = {}
            for part in ("lf", "rf"):
                p = _sibling(path, part)
                if p is None:
                    continue
                name, placement = IPOL_PARTS[part]
                ft, fv, finfo = _read_one(p, repairs, max_uncompressed_bytes)
                if finfo["rate_hz"] != info["rate_hz"]:
                    raise RecordingError(f"{finfo['rate_hz']:g} Hz where the lower-back file has "
                                         f"{info['rate_hz']:g} Hz: not one trial", p)
                for k in fv:
                    streams[f"{k}@{name}"] = _stream(k, name, ft, fv[k])
                devices[name] = {"model": "XSens MTw Awinda", "placement": placement,
                                 "source": os.path.basename(p)}
                if finfo["wraps"]:
                    devices[name]["counter_wraps"] = finfo["wraps"]
            if devices:
                meta["devices"] = devices
    rec = Recording(streams, device=device, metadata=meta, repairs=repairs, source=path)
    if warn:
        for r in repairs:
            warnings.warn(r, DamagedFileWarning, stacklevel=2)
    return finish(rec, warn=warn)


def _stream(kind: str, device: str, t_ns, v):
    note = (f"XSens normalised units x {NOMINAL_FIELD_UT:g} uT (nominal, not a measured field)" if kind == MAG
            else None)
    if device:
        return device_stream(kind, device, t_ns, v, note=note)
    return make_stream(kind, t_ns, v, note=note)


def _read_one(path: str, repairs: list[str], limit) -> tuple[np.ndarray, dict, dict]:
    """One XSens file: ``(t_ns, {stream: values}, {"rate_hz", "wraps"})``."""
    state: dict = {"rate": None, "header": None, "n": 0}
    bad: list[RecordingError] = []
    cnt = ColumnBuffer(1)
    vals: ColumnBuffer | None = None

    def chunk(first: int, lines: list[str]) -> None:
        nonlocal vals
        k = 0
        while state["header"] is None and k < len(lines):
            s = lines[k].strip()
            k += 1
            if not s or s.startswith("//"):
                m = _RATE.match(s)
                if m:
                    state["rate"] = float(m.group(1))
                continue
            m = _RATE.match(s)
            if m:
                state["rate"] = float(m.group(1))
                continue
            names = s.split()
            if COUNTER not in names or not all(c in names for c in GROUPS[ACC]):
                raise RecordingError(f"XSens export: expected a header naming {COUNTER} and Acc_X/Y/Z, got "
                                     f"{s[:120]!r}", path, first + k - 1)
            if state["rate"] is None:
                raise RecordingError("XSens export: no 'Acquisition frequency: N Hz' line before the header "
                                     "(the rate gives the time of a packet)", path, first + k - 1)
            if not 0 < state["rate"] <= 10000:
                raise RecordingError(f"XSens export: acquisition frequency {state['rate']:g} Hz is not plausible",
                                     path, first + k - 2)
            state["header"] = names
            state["groups"] = {g: [names.index(c) for c in cols] for g, cols in GROUPS.items()
                               if all(c in names for c in cols)}
            state["usecols"] = [names.index(COUNTER)] + [c for cols in state["groups"].values() for c in cols]
            vals = ColumnBuffer(len(state["usecols"]) - 1)
        if state["header"] is None:
            return
        nos = [first + k + i for i, ln in enumerate(lines[k:]) if ln.strip()]
        rows = [ln for ln in lines[k:] if ln.strip()]
        if not rows:
            return
        state["n"] += len(rows)
        nf = len(state["header"])
        _, v, kept, errs = fixed_rows(rows, state["usecols"], None, (nf, nf), int_first=False,
                                      names=state["header"])
        bad.extend(RecordingError(msg, path, nos[j]) for j, msg in errs)
        cnt.append(v[:, :1])
        vals.append(v[:, 1:])

    def tail(lineno: int, last: str) -> None:
        if not last.strip():
            return
        if state["header"] is not None and len(last.split()) == len(state["header"]):
            chunk(lineno, [last])
        else:
            repairs.append(f"{path}: dropped an incomplete last line {lineno} (no newline: the file was cut off)")

    with open_text(path, repairs, limit) as text, np.errstate(all="ignore"):
        feed_lines(text, path, repairs, chunk, bad, tail)
    if state["header"] is None:
        raise RecordingError("XSens export: no header line (PacketCounter Acc_X ...)", path)
    skip_bad_lines(bad, state["n"], path, repairs)
    if not len(cnt):
        raise RecordingError("no data lines", path)
    c = cnt.array()[:, 0]
    if not np.all(np.isfinite(c)) or np.any(c != np.round(c)) or np.any(np.abs(c) > 2 ** 52):
        j = int(np.flatnonzero(~np.isfinite(c) | (c != np.round(c)) | (np.abs(c) > 2 ** 52))[0])
        raise RecordingError(f"{COUNTER} is not a whole number: {float(c[j])!r}", path)
    counter = c.astype(np.int64)
    wraps = np.flatnonzero(np.diff(counter) < -COUNTER_RANGE // 2)
    if len(wraps):
        add = np.zeros(len(counter), dtype=np.int64)
        for w in wraps:
            add[w + 1:] += COUNTER_RANGE
        counter = counter + add
    rate = state["rate"]
    t_ns = counter * 10_000_000 if rate == 100.0 else np.round(counter * (1e9 / rate)).astype(np.int64)
    v = vals.array()
    out, k = {}, 0
    for g in state["groups"]:
        x = v[:, k:k + 3]
        out[g] = x * NOMINAL_FIELD_UT if g == MAG else x
        k += 3
    return t_ns, out, {"rate_hz": rate, "wraps": int(len(wraps))}
