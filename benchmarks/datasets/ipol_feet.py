"""IPOL healthy gait with all three sensors: lower back (primary) and both feet (``acc@left_foot`` ...).

Reuses :mod:`benchmarks.datasets.ipol` (read-only) for the files and the
annotations; only the recording differs: the lower-back XSens is the primary
device (``acc``, ``gyro``, ``mag``: a belt-worn phone), the feet are the
devices ``left_foot`` and ``right_foot`` (:mod:`core.foot.devices`), all on
the same PacketCounter clock (``t_ns = counter * 10 ms``).  Magnetometers in
XSens normalised units (scaled by ``ipol.NOMINAL_FIELD_UT``: headings only).
Split: :func:`benchmarks.foot_splits.ipol_split` by subject.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.datasets import ipol
from benchmarks.foot_splits import ipol_split
from core.conventions import ACC, GYRO, MAG
from core.foot.devices import device_stream
from core.recording import Recording

NAME = ipol.NAME
FEET = {"left_foot": "lf", "right_foot": "rf"}


def load_recording(lb_path: Path) -> Recording:
    rec = ipol.load_recording(lb_path)
    for device, suffix in FEET.items():
        p = Path(str(lb_path).replace("_lb.txt.gz", f"_{suffix}.txt.gz"))
        data = ipol._read_sensor(p)
        counter = data[:, 0].astype(np.int64)
        keep = np.concatenate([[True], np.diff(counter) > 0])
        data, counter = data[keep], counter[keep]
        t_ns = counter * ipol.SAMPLE_PERIOD_NS
        rec.streams[f"acc@{device}"] = device_stream(ACC, device, t_ns, data[:, 1:4])
        rec.streams[f"gyro@{device}"] = device_stream(GYRO, device, t_ns, data[:, 4:7])
        rec.streams[f"mag@{device}"] = device_stream(MAG, device, t_ns, data[:, 7:10] * ipol.NOMINAL_FIELD_UT,
                                                    note="XSens normalised units x nominal field (headings only)")
    rec.device = {**rec.device, "placement": "waist"}
    rec.metadata = {**rec.metadata, "devices": {d: {"model": "XSens MTw Awinda", "placement": d.replace("_", " ")}
                                                for d in FEET}}
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
