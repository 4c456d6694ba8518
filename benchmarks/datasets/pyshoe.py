"""PyShoe / University of Toronto foot-mounted dataset, VICON subset (processed .mat, see its README.md).

Folder ``pyshoe_vicon/processed/`` under the data root: one
``<YYYY-MM-DD-hh-mm-ss>.mat.gz`` per trial (MicroStrain 3DM-GX3-25 on the
foot, 200 Hz, VICON position at every sample).

What the reader returns (one :class:`PyshoeTrial` per file):

* a recording whose primary device is the foot IMU (``acc``, ``gyro``;
  placement ``"foot"``), ``t_ns`` from the file's ``ts`` (seconds).  The axes
  are the sensor's own (z points down: the accelerometer reads about
  ``(0, 0, -g)`` at rest, which *is* the specific force in a z-down frame),
  not the Android device axes; the foot filter does not need them.
* ``truth_t_ns``, ``truth_pos_m`` (n, 3): the VICON foot position at every
  sample (metres), turned into a local ENU frame.  The files' ``gt`` has z up
  (the foot rises in the swing, the floor is near z = 0) but its horizontal
  axes are mirrored against a right-handed z-up frame: read as ``(x, y, z)``
  our track fits only as a mirror image (checked on the first tuning trial),
  so ENU is ``(y, x, z)``.
* ``zv_reference``: the VICON-derived zero-velocity labels (1 = stationary)
  shipped with the file (``zv_vicon_opt``), and the other detectors' labels
  ``zv_labels`` (``shoe``, ``ared``, ``amvd``, ``mbgtd``, ``vicon``).
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
climb by about 1 cm per stride).

Reading needs scipy (benchmark side only).
"""

from __future__ import annotations

import gzip
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.datasets.base import Trial
from benchmarks.foot_splits import pyshoe_is_walking, pyshoe_split
from core.conventions import ACC, GYRO
from core.recording import Recording, make_stream

NAME = "pyshoe_vicon"
#: order of the detectors in the files' ``trial_error``
PYSHOE_DETECTORS = ("shoe", "ared", "amvd", "mbgtd", "vicon")
#: the gyroscope's lag behind the accelerometer (s), chosen on the tuning split (see above)
GYRO_DELAY_S = 0.005


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


def _load_mat(path: Path) -> dict:
    import scipy.io

    with gzip.open(path, "rb") as fh:
        return scipy.io.loadmat(io.BytesIO(fh.read()))


def _fill(trial: "PyshoeTrial", path: Path) -> Recording:
    d = _load_mat(path)
    ts = np.asarray(d["ts"], dtype=float).ravel()
    t_ns = np.round(ts * 1e9).astype(np.int64)
    imu = np.asarray(d["imu"], dtype=float)
    trial.truth_t_ns = t_ns
    gt = np.asarray(d["gt"], dtype=float)
    trial.truth_pos_m = np.column_stack([gt[:, 1], gt[:, 0], gt[:, 2]])  # mirrored horizontal axes -> ENU
    trial.zv_labels = {k[3:-4]: np.asarray(d[k]).ravel().astype(bool) for k in d if k.startswith("zv_")}
    trial.zv_reference = trial.zv_labels.get("vicon")
    trial.pyshoe_thresholds = {k[2:-4]: float(np.asarray(d[k]).ravel()[0]) for k in d
                               if k.startswith("G_") and k.endswith("_opt")}
    err = np.asarray(d["trial_error"], dtype=float).ravel()
    trial.pyshoe_errors_m = dict(zip(PYSHOE_DETECTORS, err.tolist()))
    trial.pyshoe_best = (str(np.asarray(d["best_detector"]).ravel()[0]).strip(),
                         float(np.asarray(d["best_error"]).ravel()[0]))
    streams = {ACC: make_stream(ACC, t_ns, imu[:, 0:3], note="accelerometer, sensor axes (z down)"),
               GYRO: make_stream(GYRO, t_ns, imu[:, 3:6], note="gyroscope, sensor axes (z down)")}
    return Recording(streams, device={"model": "LORD MicroStrain 3DM-GX3-25", "placement": "foot",
                                      "axes": "sensor axes, z down"},
                     metadata={"dataset": NAME, "trial": trial.name}, source=str(path))


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
                               "gyro_delay_s": GYRO_DELAY_S})
        tr.load = lambda tr=tr, p=p: _fill(tr, p)
        out.append(tr)
    return out
