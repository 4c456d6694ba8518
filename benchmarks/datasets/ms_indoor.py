"""Microsoft / XYZ10 Indoor Location Competition 2.0 sample traces with surveyor waypoints.

Folder ``ms_indoor_location_2020/site<k>/<floor>/`` (see its README.md):

* ``path_data_files/*.txt(.gz)``: tab-separated ``unix_ms  TYPE  values...``
  after ``#`` header lines (``#\\tStartTime:...``, ``Brand:...\\tModel:...``).
  Used here: ``TYPE_ACCELEROMETER x y z acc`` (m/s^2), ``TYPE_GYROSCOPE``
  (rad/s), ``TYPE_MAGNETIC_FIELD`` (uT, the OS-calibrated field) and
  ``TYPE_ROTATION_VECTOR x y z acc`` (the phone's own attitude, Android's
  rotation vector: ``w = sqrt(1 - x^2 - y^2 - z^2)``, device -> East-North-Up
  with y to magnetic north -- exactly :mod:`core`'s quaternion convention).
  ``TYPE_WAYPOINT x y`` is the surveyor's ground-truth position (m).  A line
  missing its newline (the source README warns of it) is skipped.
* ``floor_info.json``: map width and height (m).

Frames and clocks.  All timestamps are Unix milliseconds (the sensor
timestamps converted by the logging app), so waypoints and sensors share one
clock; ``t_ns = unix_ms * 10**6``.  The waypoint frame is East/North metres
from the south-west corner of the floor's GeoJSON bounding box: the map's
width and height equal the box's extent in metres (checked on site2/F3:
236.71 x 219.75 m both ways), so x is East and y is North and absolute
headings can be compared.  The site (Hangzhou, 30.30 N 120.13 E, Nov 2019)
has a magnetic declination of -5.68 deg (WMM2015v2 via
:func:`core.geodesy.declination_rad`).
The phone is "held flat in front of the body" (source README): placement
``hand_flat``.  The traces are short open paths (6-75 s); the filters get no
time to settle before the first waypoint.

Splits (:mod:`benchmarks.splits`): by ``info["file_no"]``, the 1-based number
of the trace file in its folder sorted by file name (every trace file counts,
also those skipped for having fewer than 3 waypoints).
"""

from __future__ import annotations

import datetime
import gzip
import math
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Landmarks, Site, Trial
from core.conventions import ACC, GYRO, MAG, ROTVEC
from core.recording import Recording, make_stream, repair_recording

NAME = "ms_indoor_location_2020"

#: the site (Hangzhou) and the date of the site2 traces
SITE = Site(lat_deg=30.302, lon_deg=120.131, alt_m=10.0, when=datetime.date(2019, 11, 19))

_TYPES = {"TYPE_ACCELEROMETER": ACC, "TYPE_GYROSCOPE": GYRO, "TYPE_MAGNETIC_FIELD": MAG,
          "TYPE_ROTATION_VECTOR": ROTVEC}


def available(root: Path) -> bool:
    return any((Path(root) / NAME).glob("site*/*/path_data_files"))


def _open(path: Path):
    return gzip.open(path, "rt", encoding="utf-8", errors="replace") if path.suffix == ".gz" else \
        open(path, "rt", encoding="utf-8", errors="replace")


def parse_trace(path: Path) -> tuple[Recording, Landmarks, dict]:
    """Read one trace: the sensor :class:`Recording`, its waypoints and header facts."""
    rows: dict[str, tuple[list[int], list[list[float]]]] = {n: ([], []) for n in _TYPES.values()}
    wp_t, wp_xy = [], []
    header: dict[str, str] = {}
    skipped = 0
    with _open(Path(path)) as f:
        for line in f:
            if line.startswith("#"):
                for field in line[1:].strip().split("\t"):
                    k, _, v = field.partition(":")
                    if v:
                        header[k.strip()] = v.strip()
                continue
            parts = line.rstrip("\n").split("\t")
            if len(parts) < 3:
                continue
            typ = parts[1]
            try:
                if typ == "TYPE_WAYPOINT":
                    t, xy = _waypoint(parts)
                    wp_t.append(t)
                    wp_xy.append(xy)
                    continue
                name = _TYPES.get(typ)
                if name is None:
                    continue
                if len(parts) != 6:  # x y z accuracy; anything else is a broken line
                    raise ValueError
                t = int(parts[0])
                x, y, z = float(parts[2]), float(parts[3]), float(parts[4])
            except ValueError:
                skipped += 1
                continue
            if name == ROTVEC:
                w = math.sqrt(max(0.0, 1.0 - (x * x + y * y + z * z)))
                vals = [w, x, y, z]
            else:
                vals = [x, y, z]
            rows[name][0].append(t * 1_000_000)
            rows[name][1].append(vals)
    streams = {}
    for name, (ts, vs) in rows.items():
        if ts:
            streams[name] = make_stream(name, np.array(ts, dtype=np.int64), np.array(vs, dtype=float))
    device = {k: header[k] for k in ("Brand", "Model", "AndroidName", "APILevel") if k in header}
    rec = Recording(streams, device=device, source=str(path))
    if skipped:
        rec.repairs.append(f"{path}: skipped {skipped} malformed line(s)")
    rec = repair_recording(rec, warn=False)
    return rec, _landmarks(wp_t, wp_xy), header


def _waypoint(parts: list[str]) -> tuple[int, list[float]]:
    """``unix_ms, [x, y]`` of a split ``TYPE_WAYPOINT`` line (ValueError if broken)."""
    if len(parts) != 4:
        raise ValueError("broken waypoint line")
    return int(parts[0]), [float(parts[2]), float(parts[3])]


def _landmarks(t_ms: list[int], xy: list[list[float]]) -> Landmarks:
    xy = np.array(xy, dtype=float).reshape(-1, 2)
    order = np.argsort(np.array(t_ms, dtype=np.int64), kind="stable")
    return Landmarks(t_ns=np.array(t_ms, dtype=np.int64)[order] * 1_000_000, east_m=xy[order, 0],
                     north_m=xy[order, 1])


def _waypoints_only(path: Path) -> Landmarks:
    """The waypoints alone (a cheap scan for the trial list)."""
    t, xy = [], []
    with _open(path) as f:
        for line in f:
            if "\tTYPE_WAYPOINT\t" not in line:
                continue
            try:
                ti, p = _waypoint(line.rstrip("\n").split("\t"))
            except ValueError:
                continue
            t.append(ti)
            xy.append(p)
    return _landmarks(t, xy)


def trials(root: Path, min_waypoints: int = 3) -> list[Trial]:
    """One trial per trace with at least ``min_waypoints`` waypoints (fewer give no segment to turn on)."""
    out = []
    declination = SITE.magnetic_field()[0]
    for folder in sorted((Path(root) / NAME).glob("site*/*/path_data_files")):
        site, floor = folder.parent.parent.name, folder.parent.name
        for file_no, path in enumerate(sorted(folder.glob("*.txt*"), key=lambda p: p.name), start=1):
            lm = _waypoints_only(path)
            if len(lm.t_ns) < min_waypoints:
                continue
            out.append(Trial(
                dataset=NAME, name=f"{site}/{floor}/{path.name.split('.')[0]}",
                load=(lambda p=path: parse_trace(p)[0]), placement="hand_flat", landmarks=lm,
                declination_rad=declination, site=SITE, info={"site": site, "floor": floor, "file_no": file_no},
                resolve=lambda rec: {"info": {"phone": rec.device.get("Model", "")}},
            ))
    return out
