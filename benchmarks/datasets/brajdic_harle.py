"""Brajdic & Harle (2013) hand-held walks: acc + gyro + mag with manual step counts.

Folder ``brajdic_harle_handheld/`` (see its README.md):

* ``p<person>.<walk>_<Sex>_<age>_<height>cm_Hand_held.out``: big-endian binary,
  21-byte records ``int64 t_ns, int8 type (1 acc, 2 gyro, 3 mag), float32 x, y, z``
  (numpy ``[('t','>i8'),('type','i1'),('v','>f4',3)]``); ``.dat(.gz)`` holds the
  same fields as text.  Units m/s^2, rad/s, uT; Android device axes.
  Timestamps are device uptime (ns).
* ``groundtruth_SC.txt``: manual step count per trace (``p1.1 70``).  Walks
  without a count are still listed (no step ground truth).
* ``groundtruth_WD.txt``: walk start and end as **accelerometer sample
  indices** (``p1.1Hand_held (1607 5393)``); they become ``walk_t_ns``.  The
  manual count is for that walk, so the benchmark counts our steps inside
  this window (see :mod:`benchmarks.run`).

The height band (e.g. ``170-179cm``) gives ``subject['height_m']`` as its
middle (the band covers [170, 180) cm: 1.75 m); the band is kept in ``subject['height_band']``.
"""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from core.conventions import ACC, GYRO, MAG
from core.recording import Recording, make_stream, repair_recording

NAME = "brajdic_harle_handheld"

RECORD = np.dtype([("t", ">i8"), ("type", "i1"), ("v", ">f4", 3)])
TYPES = {1: ACC, 2: GYRO, 3: MAG}

_FILE = re.compile(r"^(p\d+\.\d+)_([A-Za-z]+)_(\d+)-(\d+)_(\d+)-(\d+)cm_Hand_held\.(out|dat|dat\.gz)$")


def available(root: Path) -> bool:
    return (Path(root) / NAME / "groundtruth_SC.txt").exists()


def read_trace(path: Path) -> Recording:
    """A :class:`Recording` (acc, gyro, mag) from a ``.out`` binary or ``.dat(.gz)`` text trace."""
    path = Path(path)
    if path.name.endswith(".out"):
        d = np.fromfile(path, dtype=RECORD)
        t, typ, v = d["t"].astype(np.int64), d["type"].astype(int), d["v"].astype(np.float64)
    else:
        opener = gzip.open if path.name.endswith(".gz") else open
        with opener(path, "rt") as f:
            a = np.loadtxt(f, ndmin=2)
        # ns timestamps ~1e12: exact in float64
        t, typ, v = a[:, 0].astype(np.int64), a[:, 1].astype(int), a[:, 2:5]
    streams = {name: make_stream(name, t[typ == code], v[typ == code]) for code, name in TYPES.items()}
    rec = Recording(streams, device={}, source=str(path))
    return repair_recording(rec, warn=False)


def read_step_counts(path: Path) -> dict[str, int]:
    out = {}
    for line in Path(path).read_text().split("\n"):
        parts = line.split()
        if len(parts) >= 2 and parts[1].isdigit():
            out[parts[0]] = int(parts[1])
    return out


def read_walk_windows(path: Path) -> dict[str, tuple[int, int]]:
    out = {}
    for m in re.finditer(r"^(p\d+\.\d+)Hand_held\s*\((\d+)\s+(\d+)\)", Path(path).read_text(), re.M):
        out[m.group(1)] = (int(m.group(2)), int(m.group(3)))
    return out


def trials(root: Path) -> list[Trial]:
    base = Path(root) / NAME
    counts = read_step_counts(base / "groundtruth_SC.txt")
    windows = read_walk_windows(base / "groundtruth_WD.txt") if (base / "groundtruth_WD.txt").exists() else {}
    out = []
    for path in sorted(base.iterdir()):
        m = _FILE.match(path.name)
        if not m:
            continue
        trace, sex, a0, a1, h0, h1 = m.group(1), m.group(2), m.group(3), m.group(4), int(m.group(5)), int(m.group(6))
        window = windows.get(trace)
        height_m = (h0 + h1 + 1) / 200.0  # middle of the band: 170-179 cm -> 1.745 m
        out.append(Trial(
            dataset=NAME, name=trace, load=(lambda p=path: read_trace(p)), placement="hand",
            step_count=counts.get(trace),
            resolve=(lambda rec, w=window: {"walk_t_ns": walk_window_t_ns(rec, w)}),
            subject={"id": trace.split(".")[0], "sex": sex.lower(), "age_band": f"{a0}-{a1}",
                     "height_band": f"{h0}-{h1}cm", "height_m": height_m},
            info={"walk_samples": f"{window[0]}-{window[1]}" if window else ""},
        ))
    return out


def walk_window_t_ns(rec: Recording, window: tuple[int, int] | None) -> tuple[int, int] | None:
    """The walk window of ``groundtruth_WD.txt`` (accelerometer sample indices) as ``t_ns``."""
    if window is None:
        return None
    t = rec.stream(ACC).t_ns
    i0, i1 = max(0, window[0]), min(len(t) - 1, window[1])
    return int(t[i0]), int(t[i1])
