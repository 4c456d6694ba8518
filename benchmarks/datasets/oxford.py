"""Oxford step-counter dataset: phone accelerometer traces with foot-switch step ground truth.

Folder ``oxford_step_counter/`` (see its README.md):

* ``optimisation/data/<Phone>_<User>_<Surface>_<Placement>_<n>/``

  - ``accelerometer.csv(.gz)``: ``t_ns, accuracy, ax, ay, az`` (Android
    ``SensorEvent.timestamp`` ns since boot; m/s^2, gravity included), read
    by the importer :mod:`core.importers.oxford`.
  - ``stepcounter.csv``: ``t_ns, foot1, foot2`` on the same clock, a row about
    every 90 ms; **a step is a 0->1 transition of either foot switch** (the
    rule of the authors' corrected stats script; it reproduces ``stats.csv``).
  - ``notes.txt`` (a few folders): free text, sometimes a step count written
    by the walker ("steps 317").  It is reported as the peer ``notes`` count;
    its source is not stated and it is not an algorithm.
  - ``_Patient_*`` folders are skipped: their foot switches are stuck.

* ``validation/*.csv`` (when present -- this copy holds none): ``t_ns, ax, ay,
  az, steps_app_algorithm, steps_ground_truth_device, steps_android_hw_counter``
  with cumulative counts on every row (the importer's ``step_counts``
  stream, taken out of the recording here); the app's and Android's hardware
  counter's totals are the peer counts (``app``, ``android_hw``; the hardware
  counter is ignored when it stays 0).

Accelerometer only: no gyroscope, magnetometer or positions.  Placements are
mapped to the benchmark's labels with :data:`PLACEMENTS`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from core.importers import beside as _beside
from core.importers._common import STEP_COUNTS
from core.importers.oxford import read_oxford
from core.recording import Recording

NAME = "oxford_step_counter"

#: dataset placement word (lower case) -> benchmark placement label
PLACEMENTS = {
    "inhand": "hand",
    "hand": "hand",
    "frontpocket": "front_pocket",
    "backpocket": "back_pocket",
    "armband": "armband",
    "neckpouch": "neck_pouch",
    "purse": "bag",
    "bag": "bag",
    "swingingarm": "swinging_hand",
}


def available(root: Path) -> bool:
    d = Path(root) / NAME
    return (d / "optimisation" / "data").is_dir() or (d / "validation").is_dir()


def _find(folder: Path, stem: str) -> Path | None:
    for p in (folder / stem, folder / (stem + ".gz")):
        if p.exists():
            return p
    return None


def read_accelerometer(path: Path) -> Recording:
    """The accelerometer-only :class:`Recording` of an accelerometer or validation file (the importer's).

    A validation file's step counts (ground truth and peers) are taken out:
    the pipeline runs on the accelerometer alone.
    """
    rec = read_oxford(str(path), warn=False)
    rec.streams.pop(STEP_COUNTS, None)
    return rec


def foot_switch_steps(path: Path) -> np.ndarray:
    """Step instants (t_ns) from ``stepcounter.csv``: rows where either foot switch goes 0 -> 1
    (:func:`core.importers.beside.foot_switch_steps`, which ``pdr replay`` uses too)."""
    return _beside.foot_switch_steps(str(path))[0]


def _notes_count(folder: Path) -> int | None:
    p = folder / "notes.txt"
    if not p.exists():
        return None
    m = re.search(r"(\d+)\s*steps|steps\s*(\d+)", p.read_text(errors="replace"), re.I)
    return int(m.group(1) or m.group(2)) if m else None


def _placement(word: str) -> str:
    return PLACEMENTS.get(word.lower(), word.lower())


def _optimisation_trials(base: Path) -> list[Trial]:
    out = []
    for folder in sorted(p for p in (base / "optimisation" / "data").iterdir() if p.is_dir()):
        if folder.name.startswith("_Patient"):
            continue  # stuck foot switches (README): unusable
        acc = _find(folder, "accelerometer.csv")
        sc = folder / "stepcounter.csv"
        if acc is None or not sc.exists():
            continue
        parts = folder.name.split("_")
        phone, user, surface, placement = parts[0], parts[1], parts[2], parts[3]
        steps = foot_switch_steps(sc)
        notes = (folder / "notes.txt").read_text(errors="replace").strip() if (folder / "notes.txt").exists() else ""
        peers = {}
        n = _notes_count(folder)
        if n is not None:
            peers["notes"] = n
        out.append(Trial(
            dataset=NAME, name=folder.name, load=(lambda p=acc: read_accelerometer(p)),
            placement=_placement(placement), step_t_ns=steps, step_count=int(len(steps)),
            subject={"id": user}, peer_step_counts=peers, notes=notes,
            info={"phone": phone, "surface": surface},
        ))
    return out


def _validation_trials(base: Path) -> list[Trial]:
    out = []
    for path in sorted((base / "validation").glob("*.csv*")):
        if not (path.name.endswith(".csv") or path.name.endswith(".csv.gz")):
            continue
        counts = read_oxford(str(path), warn=False).stream(STEP_COUNTS, "a validation file's step counts")
        t = counts.t_ns
        app, gt, hw = counts.values.T
        steps = t[1:][np.diff(gt) > 0]
        peers = {"app": int(app[-1] - app[0])}
        if np.any(hw != 0):
            peers["android_hw"] = int(hw[-1] - hw[0])
        stem = path.name.split(".")[0]
        low = stem.lower()
        placement = next((lab for word, lab in sorted(PLACEMENTS.items(), key=lambda kv: -len(kv[0]))
                          if word in low), "unknown")
        out.append(Trial(
            dataset=NAME, name="validation/" + stem,
            load=(lambda p=path: read_accelerometer(p)),
            placement=placement, step_t_ns=steps, step_count=int(gt[-1] - gt[0]),
            peer_step_counts=peers, info={"phone": "Samsung S6", "part": "validation"},
        ))
    return out


def trials(root: Path) -> list[Trial]:
    base = Path(root) / NAME
    out = []
    if (base / "optimisation" / "data").is_dir():
        out += _optimisation_trials(base)
    if (base / "validation").is_dir():
        out += _validation_trials(base)
    return out
