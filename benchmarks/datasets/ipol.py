"""IPOL healthy-gait dataset (Voisard et al., IPOL 2023): XSens on the lower back, 2 x 10 m walks.

Folder ``ipol_healthy_gait_xsens/GaitData/`` under the data root (see its
README.md).  Each trial: stand, walk 10 m, U-turn, walk 10 m back, stop.

What the reader returns (one :class:`IpolTrial` per ``<subject>-<trial>.json``):

* the recording of the **lower-back** sensor (``*_lb.txt.gz``, 5th lumbar
  vertebra, the placement nearest to a belt-carried phone), placement
  ``"waist"``, read by the importer :mod:`core.importers.xsens` (the file
  format, the clock ``t_ns = PacketCounter * 10 ms`` and the units are
  documented there; this reader reads the one file, without the feet).
  Streams ``acc`` (m/s^2), ``gyro`` (rad/s) and ``mag``.  The axes are the
  XSens sensor axes, *not* the Android device axes (the step detector and
  the stride features only use the acceleration norm, which does not care).
  The magnetometer is in XSens normalised units, scaled by the importer's
  nominal :data:`NOMINAL_FIELD_UT` to look like microtesla (relative
  headings only).  The files drop packets (gaps of 1-5 samples); the
  recording keeps the real counters, so the gaps stay gaps.  The annotations
  are sample indices into the *gap-filled* signal that starts at the file's
  first counter (that is how the authors' ``import_data.load_XSens`` reads
  the files), so index ``i`` is at ``(first_counter + i) * 10 ms``.
* ground truth: footstep events ([foot-off, foot-strike] per step, left and
  right), trial and U-turn boundaries, subject height/weight/age/sex.
  ``step_t_ns`` are the foot strikes (ends of the events), sorted.
  ``distance_m`` is 20 m (the two straight legs; the path inside the U-turn
  is not measured), ``walk_t_ns`` the trial boundaries.

Caveats (stated again in the stride results): 10 m is the protocol's
nominal leg length; where exactly the walker started, and where the U-turn
began relative to the 10 m mark, is not annotated.  Step lengths derived from
"20 m / steps on the straight legs" therefore carry a few per cent of common
uncertainty.  Subject 10 has no height in its metadata.  Trial 9-4 repeats
9-3: its lower-back file is 9-3's samples plus a longer tail, with the same
footstep annotations (a defect of the source; the reader returns it as is).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from core.importers import xsens
from core.importers.beside import ipol_events, ipol_first_counter
from core.importers.xsens import read_xsens
from core.recording import Recording

NAME = "ipol_healthy_gait_xsens"

SAMPLE_PERIOD_NS = 10_000_000  #: 100 Hz
#: XSens normalised magnetic units -> uT (the importer's nominal field; only used for relative heading)
NOMINAL_FIELD_UT = xsens.NOMINAL_FIELD_UT
#: nominal length of each straight leg of the protocol (m)
LEG_LENGTH_M = 10.0


@dataclass
class IpolTrial(Trial):
    """A :class:`Trial` with the IPOL-specific annotations kept."""

    #: U-turn window (t_ns) between the two 10 m legs
    uturn_t_ns: tuple[int, int] | None = None
    #: footstep events, (n, 2) int64 t_ns of [foot-off, foot-strike], per foot
    left_steps_t_ns: np.ndarray | None = None
    right_steps_t_ns: np.ndarray | None = None
    #: the two straight legs as (t_start_ns, t_end_ns, length_m)
    legs: tuple[tuple[int, int, float], ...] = ()


def available(root: Path) -> bool:
    return (Path(root) / NAME / "GaitData").is_dir()


def first_counter(path: Path) -> int:
    """The first PacketCounter of a sensor file (the origin of the annotation indices)."""
    return ipol_first_counter(str(path))


def load_recording(path: Path) -> Recording:
    """The lower-back (or any) XSens file alone as a :class:`Recording` (see the module docstring)."""
    rec = read_xsens(str(path), warn=False, with_siblings=False)
    rec.metadata["dataset"] = NAME
    return rec


def _finite(x):
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


def _trial(meta_path: Path) -> IpolTrial:
    meta = json.loads(meta_path.read_text())
    name = meta_path.stem
    lb = meta_path.with_name(f"{name}_lb.txt.gz")
    c0 = first_counter(lb)

    ev = ipol_events(meta, c0)
    left, right, strikes, tb, ub = ev["left"], ev["right"], ev["strikes"], ev["trial"], ev["uturn"]
    height_cm = meta.get("Height")
    if height_cm is not None and not (isinstance(height_cm, (int, float)) and math.isfinite(height_cm) and height_cm > 0):
        height_cm = None  # subject 10: NaN in the metadata
    subject = {
        "id": f"ipol-{meta['Subject']}",
        "height_m": float(height_cm) / 100.0 if height_cm else None,
        "weight_kg": _finite(meta.get("Weight")),
        "age": meta.get("Age"),
        "sex": meta.get("Gender"),
    }
    legs = ((int(tb[0]), int(ub[0]), LEG_LENGTH_M), (int(ub[1]), int(tb[1]), LEG_LENGTH_M))
    return IpolTrial(
        dataset=NAME,
        name=name,
        load=lambda p=lb: load_recording(p),
        placement="waist",
        step_t_ns=strikes,
        step_count=int(len(strikes)),
        distance_m=2 * LEG_LENGTH_M,
        subject=subject,
        walk_t_ns=(int(tb[0]), int(tb[1])),
        notes="lower-back XSens; 10 m out, U-turn, 10 m back; distance_m counts the two straight legs only",
        uturn_t_ns=(int(ub[0]), int(ub[1])),
        left_steps_t_ns=left,
        right_steps_t_ns=right,
        legs=legs,
    )


def trials(root: Path) -> list[IpolTrial]:
    folder = Path(root) / NAME / "GaitData"
    if not folder.is_dir():
        return []

    def key(p: Path):
        s, t = p.stem.split("-")
        return int(s), int(t)

    return [_trial(p) for p in sorted(folder.glob("*.json"), key=key)
            if p.with_name(f"{p.stem}_lb.txt.gz").exists()]
