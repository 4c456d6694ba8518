"""Brajdic & Harle (2013) hand-held walks: acc + gyro + mag with manual step counts.

Folder ``brajdic_harle_handheld/`` (see its README.md):

* ``p<person>.<walk>_<Sex>_<age>_<height>cm_Hand_held.out`` (binary) or
  ``.dat(.gz)`` (text): acc, gyro and mag, read by the importer
  :mod:`core.importers.brajdic` (format, units, clock documented there).
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

import re
from pathlib import Path

from benchmarks.datasets.base import Trial
from core.conventions import ACC
from core.importers import beside as _beside
from core.importers.brajdic import RECORD as _RECORD
from core.importers.brajdic import read_brajdic
from core.recording import Recording

NAME = "brajdic_harle_handheld"

#: the binary trace's record layout (the importer's)
RECORD = _RECORD

_FILE = re.compile(r"^(p\d+\.\d+)_([A-Za-z]+)_(\d+)-(\d+)_(\d+)-(\d+)cm_Hand_held\.(out|dat|dat\.gz)$")


def available(root: Path) -> bool:
    return (Path(root) / NAME / "groundtruth_SC.txt").exists()


def read_trace(path: Path) -> Recording:
    """A :class:`Recording` (acc, gyro, mag) from a ``.out`` binary or ``.dat(.gz)`` text trace."""
    return read_brajdic(str(path), warn=False)


def read_step_counts(path: Path) -> dict[str, int]:
    return _beside.read_step_counts(str(path))


def read_walk_windows(path: Path) -> dict[str, tuple[int, int]]:
    return _beside.read_walk_windows(str(path))


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
