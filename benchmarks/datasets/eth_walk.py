"""The ETH Zurich Sensor Logger walk: 12 minutes outdoors, phone flat in hand, scored against its own GPS.

Folder ``sensorlogger_gps_walk_ethz/<recording>/`` (see its README.md): a
Sensor Logger v1.12 export (Android, Samsung SM-A520F, 50 Hz IMU, GPS at
about 2 Hz), read by :func:`core.importers.sensorlogger.read_sensorlogger`.
The first ~100 s are still, 100-200 s has little motion, then the walk
(~1 m/s, ~700 m, start and end 34 m apart).  Placement: flat in hand, screen
up (the README's inference from gravity); ``hand_flat``.

Replay without GPS.  :meth:`Trial.open` removes the ``gps`` stream from the
recording (it becomes the trial's :class:`ReferenceTrack`), so our pipeline
and the peers never see it.  What a live app is allowed to know and the
benchmark uses:

* the **site**: latitude, longitude and height of the first reference GPS
  fix and the recording date (``metadata["unix_offset_ns"]``), for the magnetic
  declination from the World Magnetic Model
  (:func:`core.geodesy.declination_rad`; +3.26 deg here) -- the one
  location fix an app has when it starts;
* the **start**: our track is placed at the first reference GPS fix at its time.

The heading is absolute: from the magnetometer plus the declination, never
fitted to the GPS.

Reference track: the GPS fixes as local East/North metres about the first
fix (:func:`core.geodesy.geodetic_to_enu`), on the recording clock (the
importer puts every stream on one clock), with their horizontal accuracy.
A fix counts when the receiver's own reported horizontal accuracy is at most
``MAX_HACC_M`` = 20 m.  That drops exactly the first three fixes of this
file (24.4, 24.8, 21.1 m: the phone's coarse first location, millisecond-round
timestamps, about 65 m from where the fixes settle while the phone still
lies on the table); every later fix reports at most 19.4 m (median 4.7 m).
A reference 65 m off would score the reference, not the dead reckoning:
placed at the literal first fix the same track scores 127 m instead of 72 m.
The metrics (:func:`benchmarks.run.evaluate_trial`): for each fix, the
distance between it and our position at its time, median over the fixes;
and the same after the best rotation of our track about the start (shape
error).

Known problem (data README): the calibrated magnetometer averages only
21.7 uT (uncalibrated 68.7 uT), and its dip is negative (about -24 deg against
the WMM's +63 deg).  The importer's ``mag`` stream (the calibrated one) is
used as for any other recording; nothing is special-cased for this file.

Split (:mod:`benchmarks.splits`): report.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.datasets.base import ReferenceTrack, Site, Trial
from core.conventions import GPS
from core.geodesy import geodetic_to_enu, unix_ns_to_datetime
from core.recording import Recording

NAME = "sensorlogger_gps_walk_ethz"

#: fixes reporting a worse horizontal accuracy (m) are not reference (see the module docstring)
MAX_HACC_M = 20.0


def available(root: Path) -> bool:
    return any(p.is_dir() for p in (Path(root) / NAME).glob("20*"))


def load(folder: Path) -> Recording:
    from core.importers.sensorlogger import read_sensorlogger

    return read_sensorlogger(str(folder), warn=False)


def reference_fixes(gps, max_hacc_m: float = MAX_HACC_M) -> np.ndarray:
    """Mask of the fixes that count as reference: reported horizontal accuracy <= ``max_hacc_m`` (or unknown)."""
    cols = list(gps.columns)
    if "hacc_m" not in cols:
        return np.ones(len(gps.t_ns), dtype=bool)
    hacc = gps.values[:, cols.index("hacc_m")]
    return ~(hacc > max_hacc_m)  # nan (unknown) counts


def reference_track(gps, max_hacc_m: float = MAX_HACC_M) -> ReferenceTrack:
    """The reference fixes of a ``gps`` stream (lat_deg, lon_deg, alt_m, hacc_m) about the first of them."""
    cols = list(gps.columns)
    keep = reference_fixes(gps, max_hacc_m)
    if int(np.sum(keep)) < 2:
        raise ValueError(f"fewer than 2 GPS fixes with an accuracy of {max_hacc_m} m or better")
    lat = gps.values[keep, cols.index("lat_deg")]
    lon = gps.values[keep, cols.index("lon_deg")]
    hacc = gps.values[keep, cols.index("hacc_m")] if "hacc_m" in cols else np.full(len(lat), np.nan)
    origin = (float(lat[0]), float(lon[0]))
    east, north = geodetic_to_enu(lat, lon, origin)
    return ReferenceTrack(t_ns=gps.t_ns[keep].copy(), east_m=np.asarray(east, dtype=float),
                          north_m=np.asarray(north, dtype=float), origin_lat_lon=origin,
                          hacc_m=np.asarray(hacc, dtype=float),
                          source=f"GPS (Sensor Logger Location.csv), fixes reporting <= {max_hacc_m:g} m")


def split_off_gps(rec: Recording) -> dict:
    """Remove the GPS from ``rec`` (in place) and return the Trial fields it gives: reference, site, declination."""
    if not rec.has(GPS):
        raise ValueError(f"{rec.source}: no GPS stream to score against")
    gps = rec.streams.pop(GPS)
    ref = reference_track(gps)
    cols = list(gps.columns)
    first = int(np.argmax(reference_fixes(gps)))
    alt = float(gps.values[first, cols.index("alt_m")]) if "alt_m" in cols else 0.0
    offset = rec.metadata.get("unix_offset_ns")
    if offset is None:
        raise ValueError(f"{rec.source}: no Unix time, so no date for the magnetic model")
    when = unix_ns_to_datetime(int(offset) + int(gps.t_ns[first]))
    site = Site(lat_deg=ref.origin_lat_lon[0], lon_deg=ref.origin_lat_lon[1], alt_m=alt if alt == alt else 0.0,
                when=when)
    return {"reference_track": ref, "site": site, "declination_rad": site.magnetic_field()[0],
            "info": {"phone": rec.device.get("model", ""), "gps_fixes": len(ref.t_ns),
                     "gps_fixes_dropped": int(len(gps.t_ns) - len(ref.t_ns))}}


def trials(root: Path) -> list[Trial]:
    out = []
    for folder in sorted(p for p in (Path(root) / NAME).glob("20*") if p.is_dir()):
        out.append(Trial(dataset=NAME, name=folder.name, load=(lambda f=folder: load(f)), placement="hand_flat",
                         resolve=split_off_gps, info={"place": "ETH Zurich, outdoors"}))
    return out
