"""Microsoft / XYZ10 Indoor Location Competition 2.0 sample traces with surveyor waypoints.

Folder ``ms_indoor_location_2020/site<k>/<floor>/`` (see its README.md):

* ``path_data_files/*.txt(.gz)``: the traces, read by the importer
  :mod:`core.importers.msindoor` (the format, its clock -- Unix ms, so
  waypoints and sensors share one -- units and attitude are documented
  there).  The benchmark runs on its ``acc``, ``gyro``, ``mag`` and
  ``rotvec`` streams (the phone's own attitude, exactly :mod:`core`'s
  quaternion convention); the ``waypoint`` stream (the surveyor's positions,
  floor-map metres) becomes the trial's :class:`Landmarks`, and the
  uncalibrated streams are left out.
* ``floor_info.json``: map width and height (m).

The waypoint frame is East/North metres from the south-west corner of the
floor's GeoJSON bounding box: the map's width and height equal the box's
extent in metres (checked on site2/F3: 236.71 x 219.75 m both ways), so x
is East and y is North and absolute headings can be compared.  The site
(Hangzhou, 30.30 N 120.13 E, Nov 2019) has a magnetic declination of -5.68
deg (WMM2015v2 via :func:`core.geodesy.declination_rad`).
The phone is "held flat in front of the body" (source README): placement
``hand_flat``.  The traces are short open paths (6-75 s); the filters get no
time to settle before the first waypoint.

Splits (:mod:`benchmarks.splits`): by ``info["file_no"]``, the 1-based number
of the trace file in its folder sorted by file name (every trace file counts,
also those skipped for having fewer than 3 waypoints).
"""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Landmarks, Site, Trial
from core.importers._common import GYRO_UNCAL, MAG_UNCAL, WAYPOINT
from core.importers.msindoor import read_msindoor
from core.recording import Recording

NAME = "ms_indoor_location_2020"

#: the site (Hangzhou) and the date of the site2 traces
SITE = Site(lat_deg=30.302, lon_deg=120.131, alt_m=10.0, when=datetime.date(2019, 11, 19))

#: the header fields this reader gives as the recording's device, under the trace's own names
_DEVICE_FIELDS = ("Brand", "Model", "AndroidName", "APILevel")


def available(root: Path) -> bool:
    return any((Path(root) / NAME).glob("site*/*/path_data_files"))


def parse_trace(path: Path) -> tuple[Recording, Landmarks, dict]:
    """Read one trace: the sensor :class:`Recording`, its waypoints and the header's fields."""
    rec = read_msindoor(str(path), warn=False)
    header = rec.metadata.get("trace_header", {})
    waypoints = _landmarks(rec.streams.pop(WAYPOINT, None))
    for name in (GYRO_UNCAL, MAG_UNCAL):
        rec.streams.pop(name, None)
    rec.device = {k: header[k] for k in _DEVICE_FIELDS if k in header}
    return rec, waypoints, header


def _landmarks(stream) -> Landmarks:
    if stream is None:
        return Landmarks(t_ns=np.zeros(0, dtype=np.int64), east_m=np.zeros(0), north_m=np.zeros(0))
    return Landmarks(t_ns=stream.t_ns, east_m=stream.values[:, 0].copy(), north_m=stream.values[:, 1].copy())


def _waypoints_only(path: Path) -> Landmarks:
    """The waypoints alone (a cheap read for the trial list)."""
    return _landmarks(read_msindoor(str(path), warn=False, streams=(WAYPOINT,)).streams.get(WAYPOINT))


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
