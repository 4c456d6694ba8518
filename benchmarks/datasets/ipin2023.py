"""IPIN 2023 Track 3 training logfiles (GetSensorData) with timestamped surveyed landmarks.

Folder ``ipin2023_track3/logfiles/*.txt(.gz)`` (see its README.md).  Each file
is read by :func:`core.importers.getsensordata.read_getsensordata`, which
gives ``acc``, ``gyro``, ``mag``, the phone's own attitude ``rotvec`` (the
``AHRS`` lines, Android's rotation vector) and the landmarks as a ``posi``
stream (lat_deg, lon_deg, floor, building_id, counter), already mapped from
the app clock onto the sensor clock (see that module's docstring).

Landmarks to metres.  The ``POSI`` latitude/longitude become local East/North
metres on the WGS-84 tangent plane at the **first landmark**
(:func:`core.geodesy.geodetic_to_enu`).
The first landmark is the start of the walk proper: every file begins with
20-40 s of arbitrary "calibration" motion and 20-40 s standing, and the
first landmark comes about 61 s in.  The metrics place our track at that
landmark at its time, so the motion before does not count -- but the
filters run through it and must settle.

Every training file is a closed loop (first and last landmark coincide).
Placement: hand-held in front of face or chest ("reading/typing";
``hand``).  Magnetic declination at the Museum Industriekultur, Nuremberg
(49.461 N, 11.111 E, about 310 m, 2023-06-14): +4.01 deg (WMM2020 via
:func:`core.geodesy.declination_rad`); the landmarks are in a true-north frame.

Splits (:mod:`benchmarks.splits`): by route, ``info["route"]``.
"""

from __future__ import annotations

import datetime
import re
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Landmarks, Site, Trial
from core.geodesy import geodetic_to_enu
from core.recording import Recording

NAME = "ipin2023_track3"

#: the competition site, Museum Industriekultur, Nuremberg, at the IPIN 2023 training-data time
SITE = Site(lat_deg=49.461, lon_deg=11.111, alt_m=310.0, when=datetime.date(2023, 6, 14))

_FILE = re.compile(r"TrainingTrial(\d+)_repetition(\d+)")


def available(root: Path) -> bool:
    return (Path(root) / NAME / "logfiles").is_dir()


def load(path: Path) -> Recording:
    from core.importers.getsensordata import read_getsensordata

    return read_getsensordata(str(path), warn=False)


def landmarks(rec: Recording) -> Landmarks | None:
    """The ``posi`` stream as :class:`Landmarks` in metres around the first landmark (None without it)."""
    if not rec.has("posi"):
        return None
    s = rec.streams["posi"]
    cols = list(s.columns)
    lat = s.values[:, cols.index("lat_deg")]
    lon = s.values[:, cols.index("lon_deg")]
    origin = (float(lat[0]), float(lon[0]))
    east, north = geodetic_to_enu(lat, lon, origin)
    return Landmarks(t_ns=s.t_ns.copy(), east_m=np.asarray(east, dtype=float),
                     north_m=np.asarray(north, dtype=float), origin_lat_lon=origin)


def _resolve(rec: Recording) -> dict:
    lm = landmarks(rec)
    out = {"landmarks": lm}
    if rec.device.get("model"):
        out["info"] = {"phone": rec.device["model"]}
    return out


def trials(root: Path) -> list[Trial]:
    out = []
    declination = SITE.magnetic_field()[0]
    for path in sorted((Path(root) / NAME / "logfiles").glob("*.txt*")):
        m = _FILE.search(path.name)
        route, rep = (m.group(1), m.group(2)) if m else ("?", "?")
        out.append(Trial(
            dataset=NAME, name=f"T{route}r{rep}", load=(lambda p=path: load(p)), placement="hand",
            declination_rad=declination, site=SITE, info={"route": route, "repetition": rep},
            resolve=_resolve,
        ))
    return out
