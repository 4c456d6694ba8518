"""Ground truth kept beside a recording, in the datasets' own annotation files (issue #29).

Some datasets keep their truth in a separate file next to the recording, not in the recording's format.
:func:`truth_beside` finds it and returns it as a ``step_counts`` stream with one ``ground_truth`` column
(a cumulative count: :data:`core.metrics.COUNTER_TRUTHS`), so that ``pdr replay`` and the app show the
error against it as they do for truth inside a file (a trundle wheel, the Oxford validation files):

* **Oxford step counter**, optimisation folders: ``stepcounter.csv`` (``t_ns, foot1, foot2``, the same
  boot clock as ``accelerometer.csv``) beside the accelerometer file; a step is a 0 -> 1 transition of
  either foot switch (the dataset's rule, its README).  The count starts at 0 on the first row.
* **Brajdic & Harle**: ``groundtruth_SC.txt`` (manual count per trace, ``p1.1 70``) and
  ``groundtruth_WD.txt`` (the walk's first and last **accelerometer sample index**, ``p1.1Hand_held (1607
  5393)``) in the trace's folder: the count over that window (the whole trace without a window).
* **IPOL healthy gait** (XSens): ``<subject>-<trial>.json`` beside ``<subject>-<trial>_lb.txt.gz``: the foot
  strikes of ``LeftFootEvents``/``RightFootEvents`` (``[foot-off, foot-strike]`` sample indices counted from
  the file's first PacketCounter, 10 ms a sample) from the trial's first boundary.

The benchmark readers (``benchmarks.datasets``) use the same functions.  Every other layout in the data
folder carries its truth inside the file (IPIN ``POSI``, Microsoft waypoints, PyShoe's VICON, TrundleWheel's
wheel, Oxford validation counts) or has none beside it (GPS walks: the GPS is the reference).
"""

from __future__ import annotations

import gzip
import json
import os
import re

import numpy as np

from core.importers._common import STEP_COUNTS
from core.recording import Recording, Stream, make_stream

#: the column :func:`core.metrics.truth_of` reads as the ground-truth step count
GROUND_TRUTH = "ground_truth"
#: IPOL's XSens sample period (100 Hz)
IPOL_SAMPLE_PERIOD_NS = 10_000_000

_BH_TRACE = re.compile(r"^(p\d+\.\d+)_.*_Hand_held\.(out|dat|dat\.gz)$")
_IPOL_LB = re.compile(r"^(\d+-\d+)_lb\.txt(\.gz)?$")


def foot_switch_steps(path: str) -> tuple[np.ndarray, int]:
    """``(step instants t_ns, first row's t_ns)`` of an Oxford ``stepcounter.csv``: rows where either foot
    switch goes 0 -> 1 (two feet rising in one row are two steps)."""
    s = np.loadtxt(path, delimiter=",", ndmin=2)
    t = s[:, 0].astype(np.int64)
    rises = np.diff(s[:, 1:3].astype(int), axis=0) == 1
    idx = np.concatenate([np.flatnonzero(rises.any(axis=1)), np.flatnonzero(rises.all(axis=1))]) + 1
    return np.sort(t[idx]), int(t[0])


def read_step_counts(path: str) -> dict[str, int]:
    """Brajdic & Harle ``groundtruth_SC.txt``: ``{trace: manual step count}``."""
    out = {}
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 2 and parts[1].isdigit():
                out[parts[0]] = int(parts[1])
    return out


def read_walk_windows(path: str) -> dict[str, tuple[int, int]]:
    """Brajdic & Harle ``groundtruth_WD.txt``: ``{trace: (first, last accelerometer sample index)}``."""
    with open(path, encoding="utf-8", errors="replace") as f:
        text = f.read()
    return {m.group(1): (int(m.group(2)), int(m.group(3)))
            for m in re.finditer(r"^(p\d+\.\d+)Hand_held\s*\((\d+)\s+(\d+)\)", text, re.M)}


def ipol_first_counter(path: str) -> int:
    """The first PacketCounter of an IPOL XSens file (the origin of the annotations' sample indices)."""
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rt") as fh:
        fh.readline()
        fh.readline()
        return int(float(fh.readline().split()[0]))


def ipol_events(meta: dict, first_counter: int) -> dict:
    """An IPOL trial's annotations in ``t_ns``: ``left``/``right`` ``(n, 2)`` [foot-off, foot-strike],
    ``strikes`` (sorted), ``trial`` and ``uturn`` boundaries."""
    def t_of(i) -> np.ndarray:
        return (np.asarray(i, dtype=np.int64) + first_counter) * IPOL_SAMPLE_PERIOD_NS

    left = t_of(np.asarray(meta.get("LeftFootEvents", []), dtype=np.int64).reshape(-1, 2))
    right = t_of(np.asarray(meta.get("RightFootEvents", []), dtype=np.int64).reshape(-1, 2))
    return {"left": left, "right": right, "strikes": np.sort(np.concatenate([left[:, 1], right[:, 1]])),
            "trial": t_of(meta["TrialBoundaries"]), "uturn": t_of(meta["UTurnBoundaries"])}


def _counts(t0_ns: int, steps_t_ns, what: str) -> Stream:
    t = np.concatenate([[int(t0_ns)], np.asarray(steps_t_ns, dtype=np.int64)])
    order = np.argsort(t, kind="stable")
    return make_stream(STEP_COUNTS, t[order], np.arange(len(t), dtype=float)[:, None], columns=(GROUND_TRUTH,),
                       unit="1", note=f"ground truth beside the recording: {what}")


def _find(folder: str, name: str) -> str | None:
    for n in (name, name + ".gz"):
        p = os.path.join(folder, n)
        if os.path.isfile(p):
            return p
    return None


def truth_beside(path: str, rec: Recording) -> Stream | None:
    """The ground-truth ``step_counts`` stream kept beside the recording read from ``path``, or None.

    ``rec`` is that recording (a window given in sample indices needs its accelerometer times)."""
    path = os.path.abspath(str(path))
    folder = path if os.path.isdir(path) else os.path.dirname(path)
    fmt = rec.metadata.get("source_format") if isinstance(rec.metadata, dict) else None
    name = os.path.basename(path)
    if fmt == "oxford-step-counter" and (os.path.isdir(path) or name.lower().startswith("accelerometer")):
        sc = _find(folder, "stepcounter.csv")
        if sc is not None:
            steps, t0 = foot_switch_steps(sc)
            return _counts(t0, steps, "stepcounter.csv foot switches (a step is a 0 -> 1 of either foot)")
    m = _BH_TRACE.match(name)
    if m and fmt == "brajdic-harle" and os.path.isfile(os.path.join(folder, "groundtruth_SC.txt")):
        n = read_step_counts(os.path.join(folder, "groundtruth_SC.txt")).get(m.group(1))
        acc = rec.streams.get("acc")
        if n is None or acc is None or len(acc) < 2:
            return None
        wd = os.path.join(folder, "groundtruth_WD.txt")
        win = read_walk_windows(wd).get(m.group(1)) if os.path.isfile(wd) else None
        i0, i1 = (0, len(acc) - 1) if win is None else (max(0, win[0]), min(len(acc) - 1, win[1]))
        t = acc.t_ns
        return make_stream(STEP_COUNTS, np.array([t[i0], t[i1]], np.int64), np.array([[0.0], [float(n)]]),
                           columns=(GROUND_TRUTH,), unit="1",
                           note="ground truth beside the recording: groundtruth_SC.txt's manual count over "
                                "groundtruth_WD.txt's walk window")
    m = _IPOL_LB.match(name)
    if m and fmt == "xsens":
        meta_path = os.path.join(folder, m.group(1) + ".json")
        if os.path.isfile(meta_path):
            with open(meta_path, encoding="utf-8") as f:
                ev = ipol_events(json.load(f), ipol_first_counter(path))
            return _counts(int(ev["trial"][0]), ev["strikes"], f"{m.group(1)}.json foot strikes")
    return None


def attach_truth_beside(path: str, rec: Recording) -> Recording:
    """``rec`` with the truth beside it (:func:`truth_beside`) as its ``step_counts`` stream, unless the
    recording already carries ground-truth counts (truth inside the file wins)."""
    have = rec.streams.get(STEP_COUNTS)
    if have is not None and GROUND_TRUTH in have.columns:
        return rec
    try:
        s = truth_beside(path, rec)
    except (OSError, ValueError, KeyError, json.JSONDecodeError) as e:  # a damaged annotation: no truth, said
        rec.metadata.setdefault("truth_beside_error", f"{type(e).__name__}: {e}")
        return rec
    if s is not None:
        if have is not None:  # other counters logged in the file stay; the truth is its own stream then
            return rec
        rec.streams[STEP_COUNTS] = s
    return rec
