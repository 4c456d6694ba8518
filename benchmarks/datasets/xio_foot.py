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

Recordings: the foot IMU is the primary device (``acc`` m/s^2 with
``g = 9.80665``, ``gyro`` rad/s, ``mag`` uT = 100 x G).  Sensor axes, not
Android axes.  Split: report only (:mod:`benchmarks.foot_splits`).
"""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from benchmarks.foot_splits import xio_split
from core.conventions import ACC, GYRO, MAG, STANDARD_GRAVITY_M_S2
from core.recording import Recording, make_stream, repair_recording

NAME = "xio_foot_imu"
XIMU_RATE_HZ = 256.0


def available(root: Path) -> bool:
    return (Path(root) / NAME).is_dir()


def _table(path: Path) -> np.ndarray:
    with gzip.open(path, "rt") as fh:
        fh.readline()
        return np.loadtxt(fh, delimiter=",", ndmin=2)


def load_ngimu(path: Path) -> Recording:
    d = _table(path)
    t_ns = np.round(d[:, 0] * 1e9).astype(np.int64)
    gyro = np.radians(d[:, 1:4])
    acc = d[:, 4:7] * STANDARD_GRAVITY_M_S2
    rec = Recording({ACC: make_stream(ACC, t_ns, acc), GYRO: make_stream(GYRO, t_ns, gyro)},
                    device={"model": "x-io NGIMU", "placement": "foot", "axes": "sensor axes"},
                    metadata={"dataset": NAME}, source=str(path))
    return repair_recording(rec, warn=False)


def load_ximu(path: Path) -> Recording:
    d = _table(path)
    t_ns = np.round(np.arange(len(d)) * (1e9 / XIMU_RATE_HZ)).astype(np.int64)
    return Recording({ACC: make_stream(ACC, t_ns, d[:, 4:7] * STANDARD_GRAVITY_M_S2),
                      GYRO: make_stream(GYRO, t_ns, np.radians(d[:, 1:4])),
                      MAG: make_stream(MAG, t_ns, d[:, 7:10] * 100.0)},
                     device={"model": "x-io x-IMU", "placement": "foot", "axes": "sensor axes"},
                     metadata={"dataset": NAME}, source=str(path))


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
