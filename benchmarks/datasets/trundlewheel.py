"""Trundle-wheel walks (Jeremy618/TrundleWheel): phone web-API motion + a wheel ticking every metre.

Folder ``trundlewheel_distance/`` under the data root (see its README.md).
Only the two **raw** logs (``raw/*.csv.gz``, about 400 m each, one user) are
usable for step detection; the authors' 1 Hz "conditioned" files (which the
importer reads too, for ``pdr replay``) are too coarse and are not trials here.

The raw logs are read by the importer :mod:`core.importers.trundle` (the
format, its clock and the W3C axes are documented there): ``acc`` (W3C
``accelerationIncludingGravity``, m/s^2, 0.1 m/s^2 resolution, about 59 Hz)
and ``gyro`` (``rotationRate``, rad/s), no magnetometer, no GNSS (its
Unix-epoch rows cannot be tied to the app's clock).  Ground truth is part of
the file: the wheel's cumulative metre ticks (the importer's ``wheel``
stream) become ``wheel_t_ns`` / ``wheel_m``, ``distance_m`` is the last tick
(the wheel total the authors report), and the phone's own step counter (its
``step_counts`` stream) goes to ``peer_step_counts["phone"]``; both streams
are taken out of the recording the pipeline runs on.

Placement is not documented.  The signals say it was not a steady
"texting" hold: the mean acceleration norm is 11-12 m/s^2 for minutes at a
time (centripetal acceleration of a swinging arm or a pocket), and the
gravity direction moves between the x and z axes.  We label it
``"unknown (swinging hand or pocket?)"``.  One walker, height unknown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from core.importers._common import STEP_COUNTS, WHEEL
from core.importers.trundle import read_trundle
from core.recording import Recording

NAME = "trundlewheel_distance"

_FILES = ("normal_speed_valid", "mix_of_everything_valid")


@dataclass
class TrundleTrial(Trial):
    """A :class:`Trial` with the wheel's metre ticks."""

    #: time of each wheel tick (t_ns on the recording clock) and the cumulative distance there (m)
    wheel_t_ns: np.ndarray | None = None
    wheel_m: np.ndarray | None = None


def available(root: Path) -> bool:
    return any((Path(root) / NAME / "raw" / f"{n}.csv.gz").exists() for n in _FILES)


def _read(path: Path) -> tuple[Recording, dict]:
    """The recording the pipeline runs on (acc, gyro) and the ground-truth streams taken out of it."""
    rec = read_trundle(str(path), warn=False)
    truth = {name: rec.streams.pop(name) for name in (WHEEL, STEP_COUNTS) if name in rec.streams}
    rec.metadata["dataset"] = NAME
    return rec, truth


def load_recording(path: Path) -> Recording:
    return _read(Path(path))[0]


def _trial(path: Path) -> TrundleTrial:
    truth = _read(path)[1]
    wheel, steps = truth.get(WHEEL), truth.get(STEP_COUNTS)
    total = float(wheel.values[-1, 0]) if wheel is not None else math.nan
    phone_steps = int(steps.values[-1, 0]) if steps is not None else None
    name = path.name.replace(".csv.gz", "")
    return TrundleTrial(
        dataset=NAME,
        name=name,
        load=lambda q=path: load_recording(q),
        placement="unknown (swinging hand or pocket?)",
        distance_m=total,
        subject={"id": "trundle-jeremy", "height_m": None},
        peer_step_counts={"phone": phone_steps} if phone_steps is not None else {},
        notes="one walker, ~400 m outdoors (Malmo), web DeviceMotion ~59 Hz, no magnetometer; "
              "distance from a trundle wheel (1 m ticks)",
        wheel_t_ns=wheel.t_ns.copy() if wheel is not None else None,
        wheel_m=wheel.values[:, 0].copy() if wheel is not None else None,
    )


def trials(root: Path) -> list[TrundleTrial]:
    folder = Path(root) / NAME / "raw"
    return [_trial(folder / f"{n}.csv.gz") for n in _FILES if (folder / f"{n}.csv.gz").exists()]
