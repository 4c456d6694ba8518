"""Reader for phyphox CSV exports (RWTH Aachen's phyphox app, Android and iOS).

What this reader assumes -- from phyphox's public documentation and source,
checked on the four real exports in ``../shared/data/gps_walks_phone``
(phyphox 1.1.16 on three iPhones, 1.1.13 on a Samsung SM-A325F, Android 12);
the synthetic tests are written to these assumptions
==============================================================================
Layout
    "Export data" -> "CSV" writes a zip holding one CSV per export set of the
    experiment (names vary: ``Raw Data.csv`` in the classic sensor
    experiments, ``Accelerometer.csv``, ``Gyroscope.csv`` ... in others)
    and ``meta/device.csv`` and ``meta/time.csv``.  A folder with the
    unpacked files, or a single data CSV, is read as well.
Data files
    A header row of quoted column names, then rows of numbers::

        "Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)"
        9.364549000E-3,1.003170490E0,3.543418407E0,7.366958618E0

    Columns are recognised by name and unit, not by position or file name:
    ``Time (s)`` starts a group of columns sharing that time (a file may hold
    several sensors, each with its own time column); an axis letter x/y/z and
    the unit decide the sensor: ``(m/s^2)`` acceleration *with* g (the
    "Acceleration with g" experiment; names with "Linear" -- "Acceleration
    without g" -- are not usable and are reported), ``(rad/s)`` gyroscope
    ("Gyroscope rotation rate"), ``(µT)`` magnetometer ("Magnetometer");
    ``Latitude (°)``, ``Longitude (°)``, ``Height (m)``, ``Velocity (m/s)``,
    ``Direction (°)``, ``Horizontal Accuracy (m)`` location (``gps``: speed_m_s
    and course_deg from Velocity and Direction, NaN where the phone had none,
    e.g. before its first fix with a velocity; ``Vertical Accuracy`` is not
    read -- its unit is "(°)" in the iOS header, "(m)" in Android's);
    ``Pressure (hPa)`` barometer.  Fixes stamped less than 0.5 s after a
    START are the phone's cached last location (the OS hands it over when
    phyphox subscribes; on the real walks two fixes at the same 0.02 s with
    35 m accuracy, one at 0.000 s followed by an 11.8 s gap and a 29 m jump,
    599 m accuracy at 0.05 s): dropped and noted in ``repairs``.  "Absolute ..." columns are ignored.  Rows
    whose time or required values are empty or NaN (buffers of different
    lengths in one file, or NaN where phyphox had no value) are dropped; a
    line with some but not all of a sensor's fields ("missing fields"), or
    a field that is not a number, is a bad line: skipped and counted, or,
    past 100 or 1 % of the lines, a :class:`RecordingError` naming the first.
    The export's dialect can be comma-separated with decimal points (the
    default), tab-separated, or semicolon/tab-separated with decimal commas;
    it is recognised from the header and first data line.
Units and axes
    phyphox presents every platform in Android's convention: m/s^2 with
    gravity and the Android sign (the iOS app multiplies CoreMotion's
    g-valued inertial-force readings by -9.81), rad/s, uT, in the device frame
    (x right, y up the screen, z out of it).  So values are copied unchanged,
    after a check that the acceleration magnitude is about 9.8 m/s^2
    (about 1 g means g units: converted and noted; a phone swinging in the
    hand may read a median of 1.5 g, accepted and noted in
    ``metadata["acc_unit_check"]``; anything else is a
    :class:`RecordingError`).  ``Height (m)`` is above mean sea level, not
    the WGS-84 ellipsoid of the other importers: phyphox for Android
    subtracts the EGM84 geoid height, and the iOS walks read about 1 m in
    the Netherlands, where a Sensor Logger walk gives 42 m above the
    ellipsoid and -0.5 m above sea level.  Checked on the real walks: the
    phones face up (+z) at start and stop, the gyroscope explains how the
    magnetometer's field turns (slope 0.95: rad/s, same axes), and the
    field points down (dip 54-64 deg).
Time
    ``Time (s)`` is the *experiment time*: seconds since the measurement
    first started, **not counting pauses**.  ``meta/time.csv`` lists the
    START/PAUSE events::

        "event","experiment time","system time","system time text"
        "START",0.000000000E0,1759650000.000,"2025-10-05 10:20:00.000 UTC+02:00"

    with the system time in Unix seconds (ms resolution).  A pause would glue
    two walks together without a gap, so the real elapsed time is restored:
    a sample in the run started by START ``k`` gets
    ``t = (system_k - system_0) + (experiment_time - experiment_k)``, and
    ``t_ns = round(t * 1e9)``; ``metadata["unix_offset_ns"] = system_0`` (the
    Unix time of ``t_ns = 0``).  Without ``meta/time.csv`` ``t_ns`` is the
    experiment time and absolute time is unknown.  The Android walk of
    ``gps_walks_phone`` gets its 228.9 s pause back this way; its sensor
    files also repeat some samples (same time, same values) and step back
    10 ms three times, which the timestamp repair sorts out (with a warning).
Device
    ``meta/device.csv`` has ``"property","value"`` rows (``version``,
    ``deviceModel``, ``deviceBrand``, ``deviceManufacturer``, ``deviceRelease``
    ...); the platform is "ios" when the brand/manufacturer is Apple or the
    model an iPhone/iPad, otherwise "android".
"""

from __future__ import annotations

import os
import re
import warnings
from functools import partial

import numpy as np

from core.conventions import ACC, GPS, GYRO, MAG
from core.recording import (
    MAX_UNCOMPRESSED_BYTES, DamagedFileWarning, Recording, RecordingError, make_stream, skip_bad_lines,
)
from core.importers._common import (
    EXTRA_STREAM_SPECS, PRESSURE, FileSet, acceleration_in_m_s2, finish, first_bad_time, gps_check, gps_values,
    is_zip, magnetic_dip_deg, open_text,
)
from core.importers._csv import Table, csv_rows

FORMAT = "phyphox"

_UNIT = re.compile(r"\(([^()]*)\)\s*$")
_AXIS = re.compile(r"(?:^|[\s_])([xyz])(?=$|[\s_])", re.I)
_TIME = re.compile(r"^\s*(time|t)\s*\(\s*s\s*\)\s*$", re.I)


def looks_like_csv(head: str) -> bool:
    """A phyphox data CSV starts with a (quoted) ``Time (s)`` column."""
    first = head.lstrip("\ufeff").split("\n", 1)[0].strip()
    return bool(re.match(r'^"?\s*Time \(s\)\s*"?\s*[,;\t]', first))


def looks_like_meta(names: list[str]) -> bool:
    low = [n.lower() for n in names]
    return any(n.endswith("meta/time.csv") for n in low) or any(n.endswith("meta/device.csv") for n in low)


def _dialect(header: str, first: str) -> tuple[str, bool]:
    """(delimiter, decimal_comma) from the header and the first data line."""
    quoted = {d: header.count(f'"{d}"') for d in (",", ";", "\t")}
    best = max(quoted, key=quoted.get)
    if quoted[best] == 0:
        counts = {d: header.count(d) for d in (",", ";", "\t")}
        best = max(counts, key=counts.get)
    decimal_comma = best != "," and "," in first
    return best, decimal_comma


def _classify(name: str, file_name: str) -> tuple[str, str] | None:
    """``(sensor, component)`` of a data column, or ``None`` if not used."""
    low = name.lower()
    m = _UNIT.search(name)
    unit = m.group(1).strip().lower().replace(" ", "") if m else ""
    label = name[:m.start()] if m else name
    if low.startswith("absolute"):
        return None
    if "latitude" in low:
        return ("gps", "lat")
    if "longitude" in low:
        return ("gps", "lon")
    if low.startswith("height") or low.startswith("altitude"):
        return ("gps", "alt")
    if "horizontal accuracy" in low:
        return ("gps", "hacc")
    if low.startswith("velocity") and unit == "m/s" and not _AXIS.search(label):
        return ("gps", "speed")
    if low.startswith("direction") and unit in ("°", "deg"):
        return ("gps", "course")
    if "pressure" in low and unit in ("hpa", "mbar"):
        return ("pressure", "p")
    a = _AXIS.search(label)
    if not a:
        return None
    axis = a.group(1).lower()
    if unit in ("m/s^2", "m/s²", "m/s2", "ms^-2"):
        linear = "linear" in low or "linear" in file_name.lower() or "without g" in file_name.lower()
        return ("linacc" if linear else "acc", axis)
    if unit == "rad/s":
        return ("gyro", axis)
    if unit in ("µt", "μt", "ut", "microtesla"):
        return ("mag", axis)
    return None


#: fixes stamped this soon after a START (s of experiment time) are the phone's cached last location
CACHED_FIX_WINDOW_S = 0.5


def _cached_fixes(t_s: np.ndarray, starts_s) -> np.ndarray:
    """Which fixes are the cached last location the OS hands over when phyphox subscribes (see the module doc).

    A fix stamped less than :data:`CACHED_FIX_WINDOW_S` after the START of its run: no receiver gets a
    fresh fix that fast (the location stream's own first fixes on the real walks: two identical-time
    fixes at 0.02 s with 35 m accuracy, one at 0.000 s followed by an 11.8 s gap and a 29 m jump, 599 m
    and 227 m accuracy at 0.05 s; the next fixes come 0.4-12 s later).
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    e = np.sort(np.asarray(starts_s, dtype=np.float64))
    k = np.clip(np.searchsorted(e, t_s, side="right") - 1, 0, len(e) - 1)
    since = t_s - e[k]
    return (since >= 0.0) & (since < CACHED_FIX_WINDOW_S)


def _text_dialect(text: str) -> tuple[str, bool]:
    lines = text.split("\n", 2)
    return _dialect(lines[0], lines[1] if len(lines) > 1 else "")


def _read_props(text: str, where: str) -> dict:
    out = {}
    rows = csv_rows(text, where, _text_dialect(text)[0])
    for row in rows[1:]:
        if len(row) >= 2:
            out[row[0].strip()] = row[1].strip()
    return out


def _read_events(text: str, where: str) -> list[tuple[str, float, float]]:
    delim, _ = _text_dialect(text)
    rows = csv_rows(text, where, delim)
    if not rows:
        return []
    head = [h.strip().lower() for h in rows[0]]
    try:
        ie, ix, iy = head.index("event"), head.index("experiment time"), head.index("system time")
    except ValueError:
        raise RecordingError(f"meta/time.csv: expected columns event, experiment time, system time; found "
                             f"{', '.join(rows[0])}", where, 1) from None
    out = []
    for i, row in enumerate(rows[1:], start=2):
        if not row or not any(c.strip() for c in row):
            continue
        if len(row) <= max(ie, ix, iy):
            raise RecordingError("meta/time.csv: missing fields", where, i)
        ev = row[ie].strip().upper()
        if ev not in ("START", "PAUSE"):
            continue  # phyphox: unknown events are ignored
        try:
            # a decimal comma is only possible when the delimiter is not a comma
            out.append((ev, float(row[ix].strip().replace(",", ".")), float(row[iy].strip().replace(",", "."))))
        except ValueError:
            raise RecordingError(f"meta/time.csv: time is not a number: {row[ix]!r} / {row[iy]!r}", where,
                                 i) from None
    return out


def read_phyphox(path: str, *, warn: bool = True,
                 max_uncompressed_bytes: int | None = MAX_UNCOMPRESSED_BYTES) -> Recording:
    """Read a phyphox CSV export (zip, folder or one CSV) into a :class:`Recording` (see the module doc).

    Each data file is streamed; a zip member (or gzip file) of over
    ``max_uncompressed_bytes`` is refused before it is read.
    """
    path = str(path)
    if not os.path.exists(path):
        raise RecordingError("cannot open: no such file or folder", path)
    # non-finite values pass through as data, without numpy warnings
    if os.path.isdir(path) or is_zip(path):
        with FileSet(path, max_uncompressed_bytes) as fs, np.errstate(all="ignore"):
            names = fs.names()
            data = [n for n in names if n.lower().endswith(".csv") and "meta/" not in n.lower()
                    and not n.split("/")[-1].lower() in ("device.csv", "time.csv")]
            files = [(n, fs.where(n), partial(fs.text, n)) for n in data]
            meta = {}
            for n in names:
                low = n.lower()
                if low.endswith("meta/device.csv"):
                    meta["device"] = (fs.where(n), fs.read_text(n))
                elif low.endswith("meta/time.csv"):
                    meta["time"] = (fs.where(n), fs.read_text(n))
            return _build(files, meta, path, warn, fs.repairs)
    damage: list[str] = []
    files = [(os.path.basename(path), path, partial(open_text, path, damage, max_uncompressed_bytes))]
    with np.errstate(all="ignore"):
        return _build(files, {}, path, warn, damage)


def _read_group(table: Table, ti: int, sensors, where: str, found: dict, repairs: list[str], warn: bool) -> int:
    """Read the columns of one 'Time (s)' group into ``found[sensor]``; returns the rows dropped as empty.

    Optional fields may be empty (nan): a shorter value buffer leaves all a
    sensor's fields empty, and the row is dropped for it.  A bad line -- a
    field that is not a number, or a value without a time or some but not
    all of a sensor's values -- is skipped and counted
    (:func:`core.recording.skip_bad_lines`, with a :class:`DamagedFileWarning`).
    """
    cols = sorted({c for *_, cs in sensors for c in cs})
    data = table.read([(ti, "o")] + [(c, "o") for c in cols], with_lines=True, with_empty=True)
    v, empty, line = data["v"], data["empty"], data["line"]
    bad = list(table.bad)
    picks = []
    partial_rows = np.zeros(len(v), dtype=bool)
    for sensor, need, order, cs in sensors:
        pos = [0] + [1 + cols.index(c) for c in cs]
        e = empty[:, pos[:1 + len(need)]]
        ev = e[:, 1:]
        partial = (ev.any(axis=1) & ~ev.all(axis=1)) | (e[:, 0] & ~ev.all(axis=1))
        for j in np.flatnonzero(partial & ~partial_rows):
            names = [table.header[c] for c, x in zip([ti] + cs[:len(need)], e[j]) if x]
            bad.append(RecordingError(f"missing fields: no value for {', '.join(names)}", where, int(line[j])))
        partial_rows |= partial
        picks.append((sensor, need, order, pos))
    bad.sort(key=lambda err: err.line or 0)
    skip_bad_lines(bad, table.n_lines, where, repairs)
    if warn and bad:
        warnings.warn(repairs[-1], DamagedFileWarning, stacklevel=5)
    dropped = 0
    for sensor, need, order, pos in picks:
        vals = v if pos == list(range(v.shape[1])) else v[:, pos]
        ok = np.all(np.isfinite(vals[:, :1 + len(need)]), axis=1) & ~partial_rows
        j = first_bad_time(np.where(ok, vals[:, 0], 0.0))
        if j is not None:
            raise RecordingError(f"'{table.header[ti]}' is not a usable time: {float(vals[j, 0])!r}", where,
                                 int(line[j]))
        dropped += int((~ok).sum()) - int(partial_rows.sum())
        if not ok.all():
            vals = vals[ok]
        if len(vals):
            found.setdefault(sensor, []).append((len(vals), where, order, vals))
    return dropped


def _build(files, meta, source, warn, damage: list[str]) -> Recording:
    """``files``: (name, where, opener) with ``opener()`` a context manager giving the file's lines;
    ``damage``: where the openers note gzip damage."""
    found: dict[str, list] = {}
    unused: list[str] = []
    dropped_rows = 0
    repairs: list[str] = []
    for name, where, opener in files:
        with opener() as text:
            table = Table(text, where, dialect=_dialect)
            if table.blank:
                continue
            header = table.header
            time_cols = [i for i, h in enumerate(header) if _TIME.match(h)]
            if not time_cols:
                unused.append(f"{name.split('/')[-1]} (no 'Time (s)' column)")
                continue
            bounds = time_cols + [len(header)]
            groups = []
            for g in range(len(time_cols)):
                ti = time_cols[g]
                comps: dict[str, dict[str, int]] = {}
                for c in range(ti + 1, bounds[g + 1]):
                    k = _classify(header[c], name.split("/")[-1])
                    if k is None:
                        continue
                    comps.setdefault(k[0], {}).setdefault(k[1], c)
                sensors = []
                for sensor, cols in comps.items():
                    need = {"gps": ("lat", "lon"), "pressure": ("p",)}.get(sensor, ("x", "y", "z"))
                    if not all(n in cols for n in need):
                        unused.append(f"{name.split('/')[-1]}: {sensor} without {'/'.join(need)} columns")
                        continue
                    extra = ("alt", "hacc", "speed", "course") if sensor == "gps" else ()
                    order = list(need) + [n for n in extra if n in cols]
                    sensors.append((sensor, need, order, [cols[n] for n in order]))
                if sensors:
                    groups.append((ti, sensors))
            for g, (ti, sensors) in enumerate(groups):
                if g:  # another time column of the same file: read it again
                    with opener() as again:
                        dropped_rows += _read_group(Table(again, where, dialect=_dialect), ti, sensors, where, found,
                                                    repairs, warn)
                else:
                    dropped_rows += _read_group(table, ti, sensors, where, found, repairs, warn)
        if table.dropped_tail:
            repairs.append(f"{where}: dropped an incomplete last line {table.dropped_tail}")
    if warn:
        for r in damage:  # a gzip file cut part-way: its complete lines are kept
            warnings.warn(r, DamagedFileWarning, stacklevel=3)
    repairs[:0] = damage
    if "acc" not in found and "linacc" in found:
        raise RecordingError("only linear acceleration (without g) found; export the 'Acceleration with g' "
                             "experiment: the pipeline needs acceleration including gravity", source)
    if not any(s in found for s in ("acc", "gyro", "mag", "gps", "pressure")):
        raise RecordingError("no phyphox sensor columns found (expected a 'Time (s)' column followed by "
                             "x/y/z columns in m/s^2, rad/s or µT)", source)

    # -- time: experiment time (pauses removed) -> elapsed time since the first START
    events = []
    if "time" in meta:
        events = _read_events(meta["time"][1], meta["time"][0])
    starts = [(e, s) for ev, e, s in events if ev == "START"]
    unix_offset_ns = None
    if starts:
        e_k = np.array([e for e, _ in starts])
        sys_ms = np.array([int(round(s * 1000.0)) for _, s in starts], dtype=np.int64)
        gap_ns = (sys_ms - sys_ms[0]) * 1_000_000  # real time of each START after the first, ns
        unix_offset_ns = int(sys_ms[0]) * 1_000_000

        def to_t_ns(t_s):
            k = np.clip(np.searchsorted(e_k, t_s, side="right") - 1, 0, len(e_k) - 1)
            return gap_ns[k] + np.rint((t_s - e_k[k]) * 1e9).astype(np.int64)
    else:
        def to_t_ns(t_s):
            return np.rint(t_s * 1e9).astype(np.int64)

    streams = {}
    used = {}
    notes: dict = {}
    for sensor, items in found.items():
        items.sort(key=lambda it: -it[0])  # the longest record of a sensor wins
        n, where, order, vals = items[0]
        if sensor == "linacc":  # gravity removed by the OS: the attitude filter needs it in
            unused.extend(f"{it[1].replace(os.sep, '/').split('/')[-1]}: linear acceleration (gravity removed by the "
                          "OS), not used: the pipeline reads the acceleration with g" for it in items)
            continue
        used[sensor] = where.replace(os.sep, "/").split("/")[-1]
        if len(items) > 1:
            unused.extend(f"{it[1].split('/')[-1]}: second {sensor} record" for it in items[1:])
        t_ns = to_t_ns(vals[:, 0])
        if sensor == "acc":
            v = acceleration_in_m_s2(vals[:, 1:4], used[sensor], source, repairs, notes)
            streams[ACC] = make_stream(ACC, t_ns, v)
        elif sensor == "gyro":
            streams[GYRO] = make_stream(GYRO, t_ns, vals[:, 1:4])
        elif sensor == "mag":
            zero = np.all(vals[:, 1:4] == 0.0, axis=1)  # no reading yet (uncalibrated iOS field): not a field
            dropped_rows += int(zero.sum())
            streams[MAG] = make_stream(MAG, t_ns[~zero], vals[~zero, 1:4])
        elif sensor == "gps":
            cached = _cached_fixes(vals[:, 0], [e for e, _ in starts] or [0.0])
            if cached.any():
                repairs.append(f"{where}: dropped {int(cached.sum())} fix(es) stamped within "
                               f"{CACHED_FIX_WINDOW_S:g} s of a START (experiment time "
                               f"{vals[cached, 0].min():.3f} to {vals[cached, 0].max():.3f} s): the phone's cached "
                               "last location, delivered when phyphox subscribes")
                vals, t_ns = vals[~cached], t_ns[~cached]
            cols = {c: vals[:, 1 + i] for i, c in enumerate(order)}
            streams[GPS] = make_stream(GPS, t_ns, gps_values(cols["lat"], cols["lon"], cols.get("alt"),
                                                             cols.get("hacc"), cols.get("speed"), cols.get("course")),
                                       note="phyphox location; alt_m = 'Height (m)', which phyphox gives above "
                                            "mean sea level (the geoid), not the WGS-84 ellipsoid; speed_m_s = "
                                            "'Velocity (m/s)', course_deg = 'Direction (°)' (nan where the phone "
                                            "gave none)")
            notes["gps_check"] = gps_check(t_ns, streams[GPS].values)
        elif sensor == "pressure":
            spec = EXTRA_STREAM_SPECS[PRESSURE]
            streams[PRESSURE] = make_stream(PRESSURE, t_ns, vals[:, 1:2], spec["columns"], spec["unit"],
                                            spec["note"])

    props = _read_props(meta["device"][1], meta["device"][0]) if "device" in meta else {}
    brand = (props.get("deviceBrand", "") + " " + props.get("deviceManufacturer", "")).lower()
    model = props.get("deviceModel", "")
    if "apple" in brand or model.lower().startswith(("iphone", "ipad", "ipod")):
        platform = "ios"
    elif props:
        platform = "android"
    else:
        platform = "unknown"
    device = {"platform": platform, "app": "phyphox"}
    for k_src, k_dst in (("deviceManufacturer", "manufacturer"), ("deviceBrand", "brand"), ("deviceModel", "model"),
                         ("deviceRelease", "os_version")):
        if props.get(k_src):
            device[k_dst] = props[k_src]
    meta_out = {
        "source_format": FORMAT,
        "app": "phyphox",
        "app_version": props.get("version", ""),
        "time_base": ("phyphox experiment time with the pauses of meta/time.csv restored" if starts
                      else "phyphox experiment time (no meta/time.csv: pauses unknown, absolute time unknown)"),
        "pauses": max(0, len(starts) - 1),
        "files_used": used,
        "unused": unused,
        "rows_dropped_empty": dropped_rows,
        "phyphox_device": props,
        **notes,
    }
    if unix_offset_ns is not None:
        meta_out["unix_offset_ns"] = unix_offset_ns
        meta_out["unix_time_source"] = "meta/time.csv first START system time (phone wall clock, ms)"
    if ACC in streams and MAG in streams:
        a, m = streams[ACC], streams[MAG]
        meta_out["mag_dip_deg"] = magnetic_dip_deg(a.t_ns, a.values, m.t_ns, m.values)
    rec = Recording(streams, device=device, metadata=meta_out, repairs=repairs, source=source)
    return finish(rec, warn=warn, unix_offset_ns=unix_offset_ns)
