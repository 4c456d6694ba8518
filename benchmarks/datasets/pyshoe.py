"""PyShoe / University of Toronto foot-mounted dataset, VICON subset (processed .mat, see its README.md).

Folder ``pyshoe_vicon/processed/`` under the data root: one
``<YYYY-MM-DD-hh-mm-ss>.mat.gz`` per trial (MicroStrain 3DM-GX3-25 on the
foot, 200 Hz, VICON position at every sample).

The files are read by the importer :mod:`core.importers.pyshoe` (its MAT-file
reader :mod:`core.importers.matv5` needs numpy and zlib only); the ground truth
that is part of a file comes out of the imported recording into the trial.

What the reader returns (one :class:`PyshoeTrial` per file):

* a recording whose primary device is the foot IMU (``acc``, ``gyro``;
  placement ``"foot"``), ``t_ns`` from the file's ``ts`` (seconds).  The axes
  are the sensor's own (z points down: the accelerometer reads about
  ``(0, 0, -g)`` at rest, which *is* the specific force in a z-down frame),
  not the Android device axes; the foot filter does not need them.
* ``truth_t_ns``, ``truth_pos_m`` (n, 3): the VICON foot position at every
  sample (metres), in a local ENU frame: the importer's ``posi`` stream (the
  files' ``gt`` has mirrored horizontal axes, so ENU is ``(y, x, z)``; see
  the importer), taken out of the recording.
* ``zv_reference``: the VICON-derived zero-velocity labels (1 = stationary)
  shipped with the file (``zv_vicon_opt``), and the other detectors' labels
  ``zv_labels`` (``shoe``, ``ared``, ``amvd``, ``mbgtd``, ``vicon``): the
  importer's ``zero_velocity`` stream, taken out of the recording.
* ``pyshoe_errors_m``: PyShoe's own error per detector (``trial_error``, in
  the order shoe, ared, amvd, mbgtd, vicon), and its best detector and error.
  **Each is at that detector's per-trial optimal threshold** (``G_<det>_opt``,
  ``pyshoe_thresholds``: SHOE's spans 4.75e5 to 9.75e7 over the trials, the
  VICON speed threshold 0.015 to 0.975 m/s), chosen per trial by a grid search
  on that same error with PyShoe's filter; none is a fixed configuration.  The
  error is not an RMSE: PyShoe's evaluation turns the track to VICON by one
  sample 0.8 m from the start and averages ``|e_xy| / sqrt(2)`` over samples
  (:func:`benchmarks.foot.pyshoe_metric` reproduces it).
* so ``zv_reference`` (``zv_vicon_opt``) is a VICON speed below a per-trial
  threshold chosen for the smallest error, not a stance truth: with 0.975 m/s
  (2017-11-22-11-30-14) 57 % of the samples are "still".

The 3DM-GX3's gyroscope readings lag its accelerometer's in these files: the
benchmark runs the navigator with ``gyro_delay_s = GYRO_DELAY_S`` (chosen on
the tuning split from 0, 2.5, 5, 7.5, 10 ms; without it the stance positions
climb by about 1 cm per stride).  Its gyroscope clips at about 9.15 rad/s
(``GYRO_RANGE_RAD_S``, ``FootSettings.gyro_range_rad_s``: the clipped runs are
repaired).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from benchmarks.foot_splits import pyshoe_is_walking, pyshoe_split
from core.importers._common import POSI, ZERO_VELOCITY
from core.importers.pyshoe import DETECTORS, read_pyshoe
from core.recording import Recording

NAME = "pyshoe_vicon"
#: order of the detectors in the files' ``trial_error``
PYSHOE_DETECTORS = DETECTORS
#: the gyroscope's lag behind the accelerometer (s), chosen on the tuning split (see above)
GYRO_DELAY_S = 0.005
#: the gyroscope's full scale in these files (rad/s): hard strides read flat at 9.10-9.19 rad/s about the
#: pitch axis for 5-15 samples (the 3DM-GX3-25's calibrated output clipped; :mod:`core.foot.saturation`)
GYRO_RANGE_RAD_S = 9.15


@dataclass
class PyshoeTrial(Trial):
    truth_t_ns: np.ndarray | None = None
    truth_pos_m: np.ndarray | None = None
    zv_reference: np.ndarray | None = None
    zv_labels: dict = field(default_factory=dict)
    pyshoe_errors_m: dict = field(default_factory=dict)
    pyshoe_best: tuple = ("", float("nan"))
    #: each detector's per-trial threshold behind its labels and error (``G_<detector>_opt``)
    pyshoe_thresholds: dict = field(default_factory=dict)


def available(root: Path) -> bool:
    return (Path(root) / NAME / "processed").is_dir()


def _nan(x) -> float:
    return float(x) if x is not None else math.nan  # the importer's JSON-safe metadata has None for nan


def _fill(trial: "PyshoeTrial", path: Path) -> Recording:
    rec = read_pyshoe(str(path), warn=False)
    posi = rec.streams.pop(POSI)
    zv = rec.streams.pop(ZERO_VELOCITY, None)
    meta = rec.metadata
    trial.truth_t_ns = posi.t_ns.copy()
    trial.truth_pos_m = np.asarray(posi.values, dtype=float).copy()
    trial.zv_labels = {c: zv.values[:, j].astype(bool) for j, c in enumerate(zv.columns)} if zv is not None else {}
    trial.zv_reference = trial.zv_labels.get("vicon")
    trial.pyshoe_thresholds = dict(meta.get("pyshoe_thresholds", {}))
    trial.pyshoe_errors_m = {k: _nan(v) for k, v in meta.get("pyshoe_errors_m", {}).items()}
    best = meta.get("pyshoe_best") or ["", None]
    trial.pyshoe_best = (str(best[0]), _nan(best[1]))
    meta["dataset"] = NAME
    meta["trial"] = trial.name
    return rec


def trials(root: Path) -> list[PyshoeTrial]:
    folder = Path(root) / NAME / "processed"
    if not folder.is_dir():
        return []
    files = sorted(folder.glob("*.mat.gz"))
    out = []
    for i, p in enumerate(files, start=1):
        name = p.name[: -len(".mat.gz")]
        tr = PyshoeTrial(dataset=NAME, name=name, load=lambda: None, placement="foot",
                         info={"position": i, "split": pyshoe_split(i), "walking": pyshoe_is_walking(name),
                               "gyro_delay_s": GYRO_DELAY_S, "gyro_range_rad_s": GYRO_RANGE_RAD_S})
        tr.load = lambda tr=tr, p=p: _fill(tr, p)
        out.append(tr)
    return out
