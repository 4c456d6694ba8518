"""x-io Technologies foot-mounted IMU examples (``xio_foot_imu``, see its README.md).

* ``ngimu_loops/{short_walk,long_walk}.csv.gz``: NGIMU on the foot, about
  400 Hz, ``Time (s)``, gyroscope (deg/s), accelerometer (g); no
  magnetometer.  The walks are loops: the foot ends where it started (the
  only ground truth).  Rows with a repeated time are dropped (the recording
  repair of :mod:`core.recording` keeps the first).
* ``ximu_2011/*_CalInertialAndMag.csv.gz``: x-IMU at 256 Hz (the original
  script's rate; packet numbers skip, so the time is the row index / 256),
  gyroscope (deg/s), accelerometer (g), magnetometer (G).  No ground truth
  beyond the described shapes: returned for the mode detection and as
  qualitative tracks, not scored.

The files are read by the importer :mod:`core.importers.xio` (the format,
its clock and units are documented there): the foot IMU is the primary
device (``acc`` m/s^2 with ``g = 9.80665``, ``gyro`` rad/s, ``mag`` uT = 100 x
G), sensor axes, not Android axes.  The reader adds what the dataset says and
the files do not: the IMU is on the foot (``device["placement"]``), the
x-IMU rate (256 Hz), and the loops' ground truth (the start is the end).
Split: report only (:mod:`benchmarks.foot_splits`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from benchmarks.foot_splits import xio_split
from core.importers.xio import read_xio
from core.recording import Recording

NAME = "xio_foot_imu"
XIMU_RATE_HZ = 256.0


def available(root: Path) -> bool:
    return (Path(root) / NAME).is_dir()


def _read(path: Path, **kw) -> Recording:
    rec = read_xio(str(path), warn=False, **kw)
    rec.device = {**rec.device, "placement": "foot"}
    rec.metadata["dataset"] = NAME
    return rec


def load_ngimu(path: Path) -> Recording:
    return _read(path)


def load_ximu(path: Path) -> Recording:
    return _read(path, ximu_rate_hz=XIMU_RATE_HZ)


def trials(root: Path) -> list[Trial]:
    base = Path(root) / NAME
    out = []
    for p in sorted((base / "ngimu_loops").glob("*.csv.gz")):
        name = p.name[: -len(".csv.gz")]
        out.append(Trial(dataset=NAME, name=name, load=lambda p=p: load_ngimu(p), placement="foot",
                         info={"kind": "loop", "split": xio_split(name)}))
    for p in sorted((base / "ximu_2011").glob("*.csv.gz")):
        name = p.name.split("_")[0]
        out.append(Trial(dataset=NAME, name=name, load=lambda p=p: load_ximu(p), placement="foot",
                         info={"kind": "shape", "split": xio_split(name)}))
    return out


def loop_closure_pct(stride_positions, distance_m: float) -> float:
    """Distance from the start to the last stance, in per cent of the walked distance."""
    sp = np.asarray(stride_positions, dtype=float).reshape(-1, 3)
    if len(sp) < 2 or not distance_m > 0:
        return math.nan
    return float(100.0 * math.hypot(sp[-1, 0] - sp[0, 0], sp[-1, 1] - sp[0, 1]) / distance_m)
