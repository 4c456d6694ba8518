"""IPOL healthy gait with all three sensors: lower back (primary) and both feet (``acc@left_foot`` ...).

Reuses :mod:`benchmarks.datasets.ipol` (read-only) for the annotations; only
the recording differs: the importer :mod:`core.importers.xsens` reads the
trial from its lower-back file -- the lower-back XSens is the primary device
(``acc``, ``gyro``, ``mag``: a belt-worn phone, placement ``"waist"``), the
feet are the devices ``left_foot`` and ``right_foot`` (:mod:`core.foot.devices`,
described in ``metadata["devices"]``), all on the same PacketCounter clock
(``t_ns = counter * 10 ms``).  Magnetometers in XSens normalised units
(scaled by the importer's nominal field: headings only).  Split:
:func:`benchmarks.foot_splits.ipol_split` by subject.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.datasets import ipol
from benchmarks.foot_splits import ipol_split
from core.importers.xsens import read_xsens
from core.recording import Recording

NAME = ipol.NAME
FEET = {"left_foot": "lf", "right_foot": "rf"}


def load_recording(lb_path: Path) -> Recording:
    rec = read_xsens(str(lb_path), warn=False)
    rec.metadata["dataset"] = NAME
    return rec


def trials(root: Path):
    out = []
    for tr in ipol.trials(root):
        subject = int(tr.name.split("-")[0])
        lb = Path(root) / NAME / "GaitData" / f"{tr.name}_lb.txt.gz"
        if not all(Path(str(lb).replace("_lb", f"_{s}")).exists() for s in FEET.values()):
            continue
        tr.load = lambda p=lb: load_recording(p)
        tr.info = {**tr.info, "subject_no": subject, "split": ipol_split(subject)}
        out.append(tr)
    return out
